"""The MIT Mini Cheetah task without oscillators: velocity tracking with the original parent settings."""

from __future__ import annotations

from dataclasses import dataclass, field

import torch

from gym_envs.legged_robot import LeggedRobot
from gym_envs.legged_robot_config import (
    CommandsCfg,
    ControlCfg,
    DomainRandCfg,
    EnvCfg,
    InitStateCfg,
    LeggedRobotCfg,
    ObservationsCfg,
    RewardsCfg,
)
from gym_envs.train_config import AlgorithmCfg, DistributionCfg, ModelCfg, TrainCfg

PROPRIOCEPTION = ("base_ang_vel", "projected_gravity", "commands", "dof_pos_obs", "dof_vel")


@dataclass
class MiniCheetahCfg(LeggedRobotCfg):
    env: EnvCfg = field(default_factory=lambda: EnvCfg(episode_length_s=10.0))
    control: ControlCfg = field(default_factory=lambda: ControlCfg(action_scale=(1.0,)))
    commands: CommandsCfg = field(
        default_factory=lambda: CommandsCfg(resampling_time_s=10.0, small_command_norm=0.2)
    )
    observations: ObservationsCfg = field(
        default_factory=lambda: ObservationsCfg(
            actor=("base_height", "base_lin_vel") + PROPRIOCEPTION,
            critic=("base_height", "base_lin_vel") + PROPRIOCEPTION,
            scales={"dof_vel": (100.0,)},
        )
    )
    rewards: RewardsCfg = field(
        default_factory=lambda: RewardsCfg(
            weights={
                "tracking_lin_vel": 5.0,
                "tracking_ang_vel": 5.0,
                "orientation": 1.0,
                "torques": 5e-7,
                "dof_vel": 1.0,
                "base_height": 1.0,
                "action_rate": 1e-3,
                "action_rate2": 1e-4,
                "dof_near_home": 1.0,
            },
            termination_penalty=0.01,
        )
    )
    init_state: InitStateCfg = field(default_factory=InitStateCfg)
    domain_rand: DomainRandCfg = field(
        default_factory=lambda: DomainRandCfg(randomize_friction=True, randomize_base_mass=True)
    )


@dataclass
class MiniCheetahTrainCfg(TrainCfg):
    """The parent task's learner (ORCAgym MiniCheetahRunnerCfg, facts §11)."""

    num_steps_per_env: int = 24
    max_iterations: int = 1000
    algorithm: AlgorithmCfg = field(
        default_factory=lambda: AlgorithmCfg(
            num_learning_epochs=6, num_mini_batches=6, entropy_coef=0.01, lam=0.99, learning_rate=1e-4
        )
    )
    actor: ModelCfg = field(
        default_factory=lambda: ModelCfg(hidden_dims=(256, 256, 256), distribution_cfg=DistributionCfg())
    )
    critic: ModelCfg = field(default_factory=lambda: ModelCfg(hidden_dims=(256, 256, 256)))


class MiniCheetah(LeggedRobot):
    cfg: MiniCheetahCfg

    def _sqexp(self, x):
        return torch.exp(-torch.square(x) / self.cfg.rewards.tracking_sigma)

    def _tracking_error(self, command, measured):
        if self.tracking_error_form == "absolute":
            return command - measured
        return (command - measured) / (1.0 + command.abs())

    def _reward_tracking_lin_vel(self):
        error = self._tracking_error(self.commands[:, :2], self.base_lin_vel[:, :2])
        return torch.exp(-torch.sum(error**2, dim=1) / self.cfg.rewards.tracking_sigma)

    def _reward_tracking_ang_vel(self):
        if self.cfg.rewards.yaw_tracking == "released_quartic":
            error = self.commands[:, 2] - self.base_ang_vel[:, 2]
            return self._sqexp((error / 5.0) ** 2)  # squared twice: 0.994 of the reward at a 1 rad/s error
        return self._sqexp(self._tracking_error(self.commands[:, 2], self.base_ang_vel[:, 2]))

    def _reward_orientation(self):
        return torch.sum(self._sqexp(self.projected_gravity[:, :2]), dim=1)

    def _reward_min_base_height(self):
        below = torch.clamp((self.state.base_pos[:, 2] - self.cfg.rewards.base_height_target) / 0.3, max=0.0)
        return self._sqexp(below)

    def _reward_dof_vel(self):
        return torch.sum(self._sqexp(self.joint_vel / 100.0), dim=1)

    def _reward_dof_near_home(self):
        return torch.sum(self._sqexp(self.joint_pos - self.default_joint_pos), dim=1)

    def _reward_cursorial(self):
        haa = self.joint_pos[:, 0::3]
        return -torch.mean((haa / 0.2) ** 2, dim=1)
