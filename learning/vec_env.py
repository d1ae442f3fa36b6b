"""rsl-rl `VecEnv` adapter around a gym_envs task.

The task already speaks rsl-rl's contract (TensorDict observation groups "actor"/"critic",
`extras["time_outs"]` for bootstrapping, per-term episode logs in `extras["log"]`); this adapter
only moves tensors between the task's device and the learner's, and forwards
`episode_length_buf` so that `init_at_random_ep_len` reaches the task.
"""

from __future__ import annotations

import functools

import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from gym_envs.legged_robot import LeggedRobot


class TaskVecEnv(VecEnv):
    def __init__(self, task: LeggedRobot, device: str | torch.device | None = None):
        self.task = task
        self.device = torch.device(device) if device is not None else task.device
        self.num_envs = task.num_envs
        self.num_actions = task.num_actions
        self.max_episode_length = task.max_episode_length
        self.cfg = task.cfg
        self.dt = task.dt

    # rsl-rl reassigns this attribute (random initial episode lengths), so it must reach the task.
    @property
    def episode_length_buf(self) -> torch.Tensor:
        return self.task.episode_length_buf

    @episode_length_buf.setter
    def episode_length_buf(self, value: torch.Tensor) -> None:
        self.task.episode_length_buf = value.to(self.task.device)

    @functools.cached_property
    def mirror_maps(self) -> dict[str, tuple[torch.Tensor, torch.Tensor]]:
        """The task's left-right mirror maps on the learner's device (learning.symmetry)."""
        return {key: (index.to(self.device), sign.to(self.device)) for key, (index, sign) in self.task.mirror_maps().items()}

    def get_observations(self) -> TensorDict:
        return self.task.get_observations().to(self.device)

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        obs, rewards, dones, extras = self.task.step(actions.to(self.task.device))
        if self.device != self.task.device:
            extras = dict(extras)
            extras["time_outs"] = extras["time_outs"].to(self.device)
        return obs.to(self.device), rewards.to(self.device), dones.to(self.device), extras

    def reset(self) -> TensorDict:
        return self.task.reset().to(self.device)
