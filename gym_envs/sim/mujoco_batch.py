"""CPU backend: MuJoCo's `mujoco.batch.Batch`, threaded C stepping of many copies of one model.

One control step is one `rollout` call of all substeps, so the substep loop stays
in C; the per-substep foot forces and servo torques are recorded by that call
into preallocated buffers. Results are bit-identical at any thread count.
"""

from __future__ import annotations

import mujoco
import mujoco.batch
import numpy as np
import torch

from gym_envs.sim.backend import SimState, StepResult
from gym_envs.sim.mujoco_model import MujocoModelBackend, as_index

# Warnings MuJoCo raises (and then resets the simulation for) when the state blows up.
_DIVERGENCE_WARNINGS = [
    int(mujoco.mjtWarning.mjWARN_BADQPOS),
    int(mujoco.mjtWarning.mjWARN_BADQVEL),
    int(mujoco.mjtWarning.mjWARN_BADQACC),
]
class MujocoBatchBackend(MujocoModelBackend):
    def __init__(
        self,
        model_path: str,
        num_envs: int,
        foot_sensors: tuple[str, ...],
        termination_sensors: tuple[str, ...],
        ground_geom: str = "floor",
        base_body: str = "base",
        device: str | torch.device = "cpu",
        num_threads: int = 0,
        cuda_graphs: bool = True,  # the Warp backend's knob; nothing to capture here
    ):
        self.device = torch.device(device)
        m = self._read_model(model_path, num_envs, foot_sensors, termination_sensors, ground_geom, base_body)
        self.batch = mujoco.batch.Batch(m, num_envs, nthread=num_threads)
        self.batch.reset(keyframe=self._home_key)
        self._qpos = self.batch.bind("qpos")
        self._qvel = self.batch.bind("qvel")
        self._ctrl = self.batch.bind("ctrl")
        self._records: dict[int, dict[str, np.ndarray]] = {}
        self._last_sensordata = np.zeros((num_envs, m.nsensordata))

    @property
    def num_threads(self) -> int:
        return self.batch.nthread

    # --- stepping -------------------------------------------------------------------------------

    def step(self, joint_targets: torch.Tensor, num_substeps: int) -> StepResult:
        if joint_targets.shape != (self.num_envs, self.num_joints):
            raise ValueError(
                f"joint targets must have shape ({self.num_envs}, {self.num_joints}) = (num_envs, num_joints), "
                f"got {tuple(joint_targets.shape)}"
            )
        self._ctrl[:] = joint_targets.detach().to("cpu", torch.float64).numpy()
        out = self._record_buffers(num_substeps)
        warnings_before = self.batch.warning[:, _DIVERGENCE_WARNINGS, 1].copy()
        failed = np.zeros(self.num_envs, dtype=bool)
        try:
            self.batch.rollout(num_substeps, record=("sensordata", "actuator_force"), out=out)
        except mujoco.batch.SimulationError as err:
            failed[err.ids] = True  # MuJoCo raised in these; the others ran to completion
        failed |= (self.batch.warning[:, _DIVERGENCE_WARNINGS, 1] != warnings_before).any(axis=1)
        failed |= ~np.isfinite(self._qpos).all(axis=1) | ~np.isfinite(self._qvel).all(axis=1)
        if failed.any():
            self._rescue(np.flatnonzero(failed), out)
        self._last_sensordata = out["sensordata"][:, -1]

        sensors = torch.from_numpy(out["sensordata"])
        torques = torch.from_numpy(out["actuator_force"])
        return StepResult(
            state=self.read_state(),
            foot_forces=self._force_norms(sensors, self._foot_rows).to(self.device, torch.float32),
            joint_torques=torques.to(self.device, torch.float32),
            diverged=torch.from_numpy(failed).to(self.device),
        )

    def _record_buffers(self, num_substeps: int) -> dict[str, np.ndarray]:
        out = self._records.get(num_substeps)
        if out is None:
            n, m = self.num_envs, self.model
            out = {
                "sensordata": np.zeros((n, num_substeps, m.nsensordata)),
                "actuator_force": np.zeros((n, num_substeps, m.nu)),
            }
            self._records[num_substeps] = out
        return out

    def _rescue(self, env_ids: np.ndarray, out: dict[str, np.ndarray]) -> None:
        """Put blown-up envs back to the home pose with finite, zeroed records; the task resets them properly."""
        self.batch.reset(ids=env_ids, keyframe=self._home_key)
        for buf in out.values():
            buf[env_ids] = 0.0

    @staticmethod
    def _force_norms(sensordata: torch.Tensor, rows: np.ndarray) -> torch.Tensor:
        forces = sensordata[..., rows.ravel()].reshape(*sensordata.shape[:-1], len(rows), 3)
        return torch.linalg.vector_norm(forces, dim=-1)

    def read_state(self) -> SimState:
        qpos = torch.from_numpy(self._qpos).to(self.device, torch.float32)
        qvel = torch.from_numpy(self._qvel).to(self.device, torch.float32)
        p, v = self._root_qpos, self._root_qvel
        sensors = torch.from_numpy(self._last_sensordata)
        termination = self._force_norms(sensors, self._termination_rows).amax(dim=-1)
        return SimState(
            base_pos=qpos[:, p : p + 3],
            base_quat=qpos[:, p + 3 : p + 7],
            base_lin_vel=qvel[:, v : v + 3],  # a free joint's linear velocity is in the world frame
            base_ang_vel=qvel[:, v + 3 : v + 6],  # and its angular velocity in the body frame
            joint_pos=qpos[:, self._joint_qpos],
            joint_vel=qvel[:, self._joint_qvel],
            termination_force=termination.to(self.device, torch.float32),
        )

    # --- resets and perturbations ---------------------------------------------------------------

    def reset(self, env_ids, base_pos, base_quat, base_lin_vel, base_ang_vel, joint_pos, joint_vel) -> None:
        ids = as_index(env_ids)
        if len(ids) == 0:
            return
        # The keyframe reset clears time, warm starts and actuator state; then the given state is written.
        self.batch.reset(ids=ids, keyframe=self._home_key, stage=mujoco.mjtStage.mjSTAGE_NONE)
        qpos, qvel = self._qpos[ids], self._qvel[ids]
        p, v = self._root_qpos, self._root_qvel
        qpos[:, p : p + 3] = _np(base_pos)
        qpos[:, p + 3 : p + 7] = _np(base_quat)
        qpos[:, self._joint_qpos] = _np(joint_pos)
        qvel[:, v : v + 3] = _np(base_lin_vel)
        qvel[:, v + 3 : v + 6] = _np(base_ang_vel)
        qvel[:, self._joint_qvel] = _np(joint_vel)
        self._qpos[ids], self._qvel[ids] = qpos, qvel
        self._last_sensordata[ids] = 0.0

    def push_base(self, env_ids, delta_vel_xy) -> None:
        ids = as_index(env_ids)
        v = self._root_qvel
        self._qvel[ids, v : v + 2] += _np(delta_vel_xy)

    def set_ground_friction(self, env_ids, friction) -> None:
        ids = as_index(env_ids)
        self.batch.expand("geom_friction")[ids, self._ground_geom, 0] = _np(friction)

    def set_base_mass_offset(self, env_ids, added_mass) -> None:
        ids = as_index(env_ids)
        self.batch.expand("body_mass")[ids, self._base_body] = self.model.body_mass[self._base_body] + _np(added_mass)
        self.batch.set_const(ids)  # subtree masses and the mass matrix constants follow the new mass

    def set_base_com_offset(self, env_ids, offset) -> None:
        ids = as_index(env_ids)
        self.batch.expand("body_ipos")[ids, self._base_body] = self.model.body_ipos[self._base_body] + _np(offset)
        self.batch.set_const(ids)

    def copy_state_to(self, env_id: int, data: mujoco.MjData) -> None:
        self.batch.get_data(env_id, data)

    def ground_friction(self) -> np.ndarray:
        """Per-env floor friction as the physics sees it (for tests and logs)."""
        expanded = self.batch.expanded("geom_friction")
        if expanded is None:
            return np.full(self.num_envs, self.model.geom_friction[self._ground_geom, 0])
        return expanded[:, self._ground_geom, 0].copy()


def _np(values) -> np.ndarray:
    if isinstance(values, torch.Tensor):
        return values.detach().to("cpu", torch.float64).numpy()
    return np.asarray(values, dtype=np.float64)
