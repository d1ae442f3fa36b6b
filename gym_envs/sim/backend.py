"""The interface every physics backend implements; tasks talk only to this.

A backend simulates `num_envs` copies of one robot model. It knows nothing of
rewards, commands or oscillators: it resets chosen envs to given states, steps
all of them a number of physics substeps under held joint-position targets, and
hands back torch tensors on the task's device. A GPU backend (MuJoCo Warp)
implements the same methods.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np
import torch


class SimSetupError(ValueError):
    """A model file or a backend argument that cannot work; the message says which."""


@dataclass
class SimState:
    """Robot state after a step, float32 on the task's device. Quaternions are (w, x, y, z)."""

    base_pos: torch.Tensor  # (N, 3) world frame
    base_quat: torch.Tensor  # (N, 4)
    base_lin_vel: torch.Tensor  # (N, 3) world frame
    base_ang_vel: torch.Tensor  # (N, 3) body frame
    joint_pos: torch.Tensor  # (N, J) in the backend's joint order
    joint_vel: torch.Tensor  # (N, J)
    termination_force: torch.Tensor  # (N,) largest net contact force [N] on the bodies that end an episode


@dataclass
class StepResult:
    state: SimState
    foot_forces: torch.Tensor  # (N, substeps, F) norm of each foot's net contact force [N], every substep
    joint_torques: torch.Tensor  # (N, substeps, J) torque the servos applied [N m], every substep
    diverged: torch.Tensor  # (N,) bool: the simulation blew up; the task must reset these envs


class SimBackend(ABC):
    """Batched simulation of one legged robot. Model facts are read from the model, never assumed."""

    num_envs: int
    device: torch.device
    timestep: float  # physics step [s]
    joint_names: tuple[str, ...]
    foot_names: tuple[str, ...]
    robot_mass: float  # [kg], summed over the robot's bodies
    gravity: float  # [m/s^2], magnitude
    default_joint_pos: torch.Tensor  # (J,) from the model's 'home' keyframe
    joint_pos_limits: torch.Tensor  # (J, 2)
    torque_limits: torch.Tensor  # (J,)
    # Geometry at the home keyframe in the base frame (numpy), for the left-right mirror maps:
    joint_anchors: np.ndarray  # (J, 3) [m]
    joint_axes: np.ndarray  # (J, 3) unit vectors
    foot_positions: np.ndarray  # (L, 3) [m]

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    @property
    def robot_weight(self) -> float:
        """[N]; the normaliser of the ground reaction forces."""
        return self.robot_mass * self.gravity

    @abstractmethod
    def reset(
        self,
        env_ids: torch.Tensor,
        base_pos: torch.Tensor,
        base_quat: torch.Tensor,
        base_lin_vel: torch.Tensor,
        base_ang_vel: torch.Tensor,
        joint_pos: torch.Tensor,
        joint_vel: torch.Tensor,
    ) -> None:
        """Put envs `env_ids` in the given state (rows match env_ids) with fresh solver warm starts."""

    @abstractmethod
    def step(self, joint_targets: torch.Tensor, num_substeps: int) -> StepResult:
        """Advance every env `num_substeps` physics steps holding joint_targets (N, J)."""

    @abstractmethod
    def read_state(self) -> SimState:
        """The current state, without stepping."""

    @abstractmethod
    def set_ground_friction(self, env_ids: torch.Tensor, friction: torch.Tensor) -> None:
        """Sliding friction of the floor, per env."""

    @abstractmethod
    def set_base_mass_offset(self, env_ids: torch.Tensor, added_mass: torch.Tensor) -> None:
        """Add mass [kg] to the base body, per env, relative to the model's value."""

    @abstractmethod
    def set_base_com_offset(self, env_ids: torch.Tensor, offset: torch.Tensor) -> None:
        """Shift the base's centre of mass by offset (n, 3) [m], relative to the model's value."""

    @abstractmethod
    def push_base(self, env_ids: torch.Tensor, delta_vel_xy: torch.Tensor) -> None:
        """Add a planar world-frame velocity (n, 2) [m/s] to the bases of env_ids."""
