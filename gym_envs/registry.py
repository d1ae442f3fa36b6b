"""Task registry: a name gives a task class and its default config."""

from __future__ import annotations

import os

from gym_envs.config import ConfigError
from gym_envs.legged_robot import LeggedRobot
from gym_envs.legged_robot_config import LeggedRobotCfg
from gym_envs.mini_cheetah import MiniCheetah, MiniCheetahCfg
from gym_envs.mini_cheetah_osc import MiniCheetahOsc, MiniCheetahOscCfg

TASKS: dict[str, tuple[type[LeggedRobot], type[LeggedRobotCfg]]] = {
    "mini_cheetah": (MiniCheetah, MiniCheetahCfg),
    "mini_cheetah_osc": (MiniCheetahOsc, MiniCheetahOscCfg),
}


class UnknownTaskError(ConfigError):
    pass


def task_entry(name: str) -> tuple[type[LeggedRobot], type[LeggedRobotCfg]]:
    if name not in TASKS:
        raise UnknownTaskError(f"unknown task {name!r}; known tasks: {', '.join(sorted(TASKS))}")
    return TASKS[name]


def env_cfg_class(name: str) -> type[LeggedRobotCfg]:
    return task_entry(name)[1]


def make_env(name: str, cfg: LeggedRobotCfg | None = None) -> LeggedRobot:
    """Build task `name` from cfg (its defaults when None)."""
    task_class, cfg_class = task_entry(name)
    cfg = cfg_class() if cfg is None else cfg
    if not isinstance(cfg, cfg_class):
        raise ConfigError(f"task {name!r} needs a {cfg_class.__name__}, got a {type(cfg).__name__}")
    check_mujoco_loads()
    return task_class(cfg)


# What each MUJOCO_GL backend needs installed (Debian/Ubuntu package names).
GL_LIBRARIES = {"osmesa": "libosmesa6", "egl": "libegl1", "glfw": "libglfw3 and a display"}


def check_mujoco_loads() -> None:
    """MuJoCo loads the OpenGL backend that MUJOCO_GL names when it is imported; a backend that is not
    installed is a one-line ConfigError naming the fix, not an AttributeError from inside PyOpenGL."""
    try:
        import mujoco  # noqa: F401
    except Exception as err:  # noqa: BLE001 - PyOpenGL fails in several ways when its library is missing
        gl = os.environ.get("MUJOCO_GL")
        if not gl:
            raise
        needs = GL_LIBRARIES.get(gl.lower(), "its OpenGL library")
        raise ConfigError(
            f"MuJoCo cannot load the OpenGL backend MUJOCO_GL={gl} ({type(err).__name__}: {' '.join(str(err).split())}); "
            f"install {needs}, or use another backend (MUJOCO_GL=egl), or unset MUJOCO_GL when nothing is rendered"
        ) from None
