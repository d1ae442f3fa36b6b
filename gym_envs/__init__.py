"""orcgym tasks: legged robots on batched MuJoCo, with decentralised phase oscillators."""

from gym_envs.config import ConfigError
from gym_envs.registry import TASKS, UnknownTaskError, env_cfg_class, make_env

__all__ = ["TASKS", "ConfigError", "UnknownTaskError", "env_cfg_class", "make_env"]
