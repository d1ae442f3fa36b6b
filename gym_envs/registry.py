"""Task registry: one entry per task names its task class, env config, train config and CPU recipe.

    register("my_robot", MyRobot, MyRobotCfg, MyRobotTrainCfg)   # cpu_profile="..." for its own CPU recipe

is all a new task needs for `train.py --task my_robot`, play.py and the analysis to find it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from gym_envs.config import ConfigError
from gym_envs.legged_robot import LeggedRobot
from gym_envs.legged_robot_config import LeggedRobotCfg
from gym_envs.mini_cheetah import MiniCheetah, MiniCheetahCfg, MiniCheetahTrainCfg
from gym_envs.mini_cheetah_osc import MiniCheetahOsc, MiniCheetahOscCfg
from gym_envs.train_config import TrainCfg


@dataclass(frozen=True)
class TaskSpec:
    task_class: type[LeggedRobot]
    env_cfg: type[LeggedRobotCfg]
    train_cfg: type[TrainCfg]
    cpu_profile: str | None  # a profile of learning.runner_config.PROFILES run on a CPU without --profile;
    # None: the generic CPU recipe (learning.machine.CPU_PROFILE)


TASKS: dict[str, TaskSpec] = {}


def register(name: str, task_class: type[LeggedRobot], env_cfg: type[LeggedRobotCfg], train_cfg: type[TrainCfg],
             cpu_profile: str | None = None) -> None:
    TASKS[name] = TaskSpec(task_class, env_cfg, train_cfg, cpu_profile)


register("mini_cheetah", MiniCheetah, MiniCheetahCfg, MiniCheetahTrainCfg)
# The paper's learner settings are TrainCfg's defaults. cpu_fast trains ORC-111 to pronk whatever its
# oscillators say; under cpu_oscillators it follows them walking forward; cpu_envelope, the CPU recipe, keeps
# that over the paper's whole command envelope (docs/recipe-study.md, E52).
register("mini_cheetah_osc", MiniCheetahOsc, MiniCheetahOscCfg, TrainCfg, cpu_profile="cpu_envelope")


class UnknownTaskError(ConfigError):
    pass


def task_entry(name: str) -> TaskSpec:
    if name not in TASKS:
        raise UnknownTaskError(f"unknown task {name!r}; known tasks: {', '.join(sorted(TASKS))}")
    return TASKS[name]


def env_cfg_class(name: str) -> type[LeggedRobotCfg]:
    return task_entry(name).env_cfg


def train_cfg_class(name: str) -> type[TrainCfg]:
    return task_entry(name).train_cfg


def make_env(name: str, cfg: LeggedRobotCfg | None = None) -> LeggedRobot:
    """Build task `name` from cfg (its defaults when None)."""
    spec = task_entry(name)
    task_class, cfg_class = spec.task_class, spec.env_cfg
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
