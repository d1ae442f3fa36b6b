"""Task registry: a name gives a task class and its default config."""

from __future__ import annotations

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
    return task_class(cfg)
