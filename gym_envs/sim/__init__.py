"""Physics backends behind one interface (`SimBackend`); tasks pick one by name."""

from __future__ import annotations

from gym_envs.sim.backend import SimBackend, SimSetupError, SimState, StepResult

BACKENDS = ("mujoco", "warp")


def make_backend(name: str, **kwargs) -> SimBackend:
    """Build the backend `name` ('mujoco': CPU threads; 'warp': MuJoCo Warp, optional extra)."""
    if name == "mujoco":
        from gym_envs.sim.mujoco_batch import MujocoBatchBackend

        return MujocoBatchBackend(**kwargs)
    if name == "warp":
        from gym_envs.sim.mujoco_warp import MujocoWarpBackend

        return MujocoWarpBackend(**kwargs)
    raise SimSetupError(f"unknown simulation backend {name!r}; choose one of {', '.join(BACKENDS)}")


__all__ = ["BACKENDS", "SimBackend", "SimSetupError", "SimState", "StepResult", "make_backend"]
