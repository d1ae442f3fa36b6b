"""Typed configuration of a legged-robot task. Tasks subclass these and change defaults.

Every field can be set from the command line as `section.key=value` (see gym_envs.config) and
is saved as YAML next to each run's checkpoints, so a run can be rebuilt exactly.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import ClassVar

from gym_envs.config import OPEN_KEYS, Check, ConfigError, OneOf, Ordered, Range, check_values

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@dataclass
class EnvCfg:
    num_envs: int = 4096
    episode_length_s: float = 4.0
    seed: int = 0
    device: str = "cpu"  # where the task's tensors live; physics of the 'mujoco' backend stays on CPU threads


@dataclass
class SimCfg:
    backend: str = "mujoco"  # 'mujoco' (CPU threads) or 'warp' (MuJoCo Warp, optional extra)
    model_path: str = "resources/robots/mini_cheetah/scene.xml"  # relative paths are from the repository root
    num_threads: int = 0  # 0: all cores
    # 'warp' on CUDA: replay each control step as a CUDA graph; false steps eagerly (~13x slower), for a
    # driver older than 12.4 or a memory pool that is off (with true those refuse to start).
    cuda_graphs: bool = True
    foot_sensors: tuple[str, ...] = ("RF_foot_force", "LF_foot_force", "RH_foot_force", "LH_foot_force")
    termination_sensors: tuple[str, ...] = ("base_force",)
    termination_force: float = 1.0  # [N] contact force on those bodies that ends an episode


@dataclass
class ControlCfg:
    """Actions are joint-position offsets from the default pose, times action_scale (per joint of a leg)."""

    frequency_hz: float = 100.0  # the physics timestep comes from the model; decimation = its ratio to this
    action_scale: tuple[float, ...] = (0.2, 0.3, 0.3)
    clip_actions: float = 1000.0


@dataclass
class CommandsCfg:
    """(v_x, v_y, yaw rate) in the body frame, redrawn at reset and every resampling_time_s."""

    resampling_time_s: float = 3.0
    lin_vel_x: tuple[float, float] = (-1.0, 1.0)
    # When not empty, v_x is one of these values plus N(0, lin_vel_x_noise^2) instead of lin_vel_x.
    lin_vel_x_choices: tuple[float, ...] = ()
    lin_vel_x_noise: float = 0.0
    lin_vel_y: tuple[float, float] = (-1.0, 1.0)
    yaw_rate: tuple[float, float] = (-1.0, 1.0)
    small_command_norm: float = 0.0  # planar commands at or below this norm are zeroed
    # Independent masks applied after drawing (probabilities per draw).
    zero_lateral_and_yaw_prob: float = 0.0
    zero_planar_prob: float = 0.0
    zero_all_prob: float = 0.0


@dataclass
class ObservationsCfg:
    """Named terms, each divided by its scale; actor terms get uniform noise of half-width noise/scale."""

    actor: tuple[str, ...] = ()
    critic: tuple[str, ...] = ()
    # One value, or one per joint of a leg (repeated over legs), or one per element.
    scales: dict[str, tuple[float, ...]] = field(default_factory=dict)
    noise: dict[str, tuple[float, ...]] = field(default_factory=dict)  # half-widths in physical units
    noise_scale: float = 1.0  # 0 turns actor noise off


@dataclass
class RewardStageCfg:
    """Reward settings that take over once the env has run `start_step` control steps (its
    common_step_counter; a PPO iteration is train.num_steps_per_env of them, and a resumed run starts
    the counter at the checkpoint's iteration): a two-stage reward curriculum, e.g. absolute tracking
    errors and stronger phase rewards once the policy walks (docs/recipe-study.md, E25-E27)."""

    start_step: int = 0  # 0: no second stage
    # Replace these entries of rewards.weights; validate() checks the names, so overrides may add any of them.
    weights: dict[str, float] = field(default_factory=dict, metadata={OPEN_KEYS: True})
    tracking_error: str = ""  # '' keeps rewards.tracking_error


@dataclass
class RewardsCfg:
    """weights[name] multiplies the task's _reward_<name>; the sum is scaled by the control dt."""

    weights: dict[str, float] = field(default_factory=dict)
    termination_penalty: float = 0.0  # subtracted on a terminated step, not scaled by dt
    tracking_sigma: float = 0.25
    # Yaw-rate tracking: 'sqexp' of the error relative to the command, like the linear term (the paper's
    # squared exponential, with a gradient across the whole +-3 rad/s range); 'released_quartic' is the
    # released code's exp(-4 ((c - w) / 5)^4), nearly flat within 1 rad/s (docs/design.md).
    yaw_tracking: str = "sqexp"
    # 'relative' divides each tracking error by 1 + |command| (released code), so a shortfall at 3 m/s
    # costs a sixteenth of the same shortfall at rest; 'absolute' holds every command to one width.
    tracking_error: str = "relative"
    base_height_target: float = 0.33
    second_stage: RewardStageCfg = field(default_factory=RewardStageCfg)


@dataclass
class InitStateCfg:
    """How envs are reset: 'range' draws the base velocity from ranges; 'default' is the home pose at rest."""

    mode: str = "default"
    base_height: float = 0.33
    lin_vel_x: tuple[float, float] = (0.0, 0.0)
    lin_vel_y: tuple[float, float] = (0.0, 0.0)
    lin_vel_z: tuple[float, float] = (0.0, 0.0)
    haa_noise: float = 0.0  # abduction joints start within +- this of the default [rad]
    # Share of timed-out (not terminated) envs whose pose is re-initialised; the rest keep moving.
    timeout_reset_ratio: float = 1.0


@dataclass
class PushCfg:
    enabled: bool = False
    interval_s: float = 10.0  # all envs are pushed at once, every interval
    max_vel_xy: float = 0.2  # [m/s] added to the base velocity, uniform in +-


@dataclass
class DomainRandCfg:
    randomize_friction: bool = False
    friction_range: tuple[float, float] = (0.5, 1.25)
    friction_buckets: int = 64  # values drawn once; each env picks one for the whole run
    # MuJoCo combines frictions with max; the floor gets (robot + ground) / 2 to mimic PhysX's average.
    ground_friction: float = 1.0
    randomize_base_mass: bool = False
    added_mass_range: tuple[float, float] = (-1.0, 1.0)
    randomize_base_com: bool = False
    com_offset_range: tuple[tuple[float, float], tuple[float, float], tuple[float, float]] = (
        (0.0, 0.0),
        (0.0, 0.0),
        (0.0, 0.0),
    )


def model_file(path: str) -> str:
    """sim.model_path as a file path (relative paths are from the repository root)."""
    return path if os.path.isabs(path) else os.path.join(REPO_ROOT, path)


POSITIVE, NON_NEGATIVE, SHARE = Range(0.0, low_open=True), Range(0.0), Range(0.0, 1.0)


@dataclass
class LeggedRobotCfg:
    # What the values may be, beyond their types (all floats must also be finite); tasks extend it.
    RULES: ClassVar[dict] = {
        "env.num_envs": Range(1),
        "env.episode_length_s": POSITIVE,
        "env.device": Check(lambda d: d in ("cpu", "cuda") or d.startswith("cuda:"), "cpu, cuda or cuda:<index>"),
        "sim.backend": OneOf(("mujoco", "warp")),
        "sim.model_path": Check(lambda p: os.path.isfile(model_file(p)), "an existing MJCF file"),
        "sim.num_threads": Range(0),
        "sim.foot_sensors": Check(len, "at least one sensor name"),
        "sim.termination_force": NON_NEGATIVE,
        "control.frequency_hz": POSITIVE,
        "control.action_scale": (Check(len, "at least one value"), POSITIVE),
        "control.clip_actions": POSITIVE,
        "commands.resampling_time_s": POSITIVE,
        "commands.lin_vel_x": Ordered(),
        "commands.lin_vel_x_noise": NON_NEGATIVE,
        "commands.lin_vel_y": Ordered(),
        "commands.yaw_rate": Ordered(),
        "commands.small_command_norm": NON_NEGATIVE,
        "commands.zero_lateral_and_yaw_prob": SHARE,
        "commands.zero_planar_prob": SHARE,
        "commands.zero_all_prob": SHARE,
        "observations.actor": Check(len, "at least one observation term"),
        "observations.critic": Check(len, "at least one observation term"),
        "observations.scales": POSITIVE,
        "observations.noise": NON_NEGATIVE,
        "observations.noise_scale": NON_NEGATIVE,
        "rewards.tracking_sigma": POSITIVE,
        "rewards.base_height_target": POSITIVE,
        "init_state.mode": OneOf(("range", "default")),
        "rewards.yaw_tracking": OneOf(("sqexp", "released_quartic")),
        "rewards.tracking_error": OneOf(("relative", "absolute")),
        "rewards.second_stage.start_step": Range(0),
        "rewards.second_stage.tracking_error": OneOf(("", "relative", "absolute")),
        "init_state.base_height": POSITIVE,
        "init_state.lin_vel_x": Ordered(),
        "init_state.lin_vel_y": Ordered(),
        "init_state.lin_vel_z": Ordered(),
        "init_state.haa_noise": NON_NEGATIVE,
        "init_state.timeout_reset_ratio": SHARE,
        "push.interval_s": POSITIVE,
        "push.max_vel_xy": NON_NEGATIVE,
        "domain_rand.friction_range": (Ordered(), NON_NEGATIVE),
        "domain_rand.friction_buckets": Range(1),
        "domain_rand.ground_friction": NON_NEGATIVE,
        "domain_rand.added_mass_range": Ordered(),
        "domain_rand.com_offset_range": Ordered(),
    }

    env: EnvCfg = field(default_factory=EnvCfg)
    sim: SimCfg = field(default_factory=SimCfg)
    control: ControlCfg = field(default_factory=ControlCfg)
    commands: CommandsCfg = field(default_factory=CommandsCfg)
    observations: ObservationsCfg = field(default_factory=ObservationsCfg)
    rewards: RewardsCfg = field(default_factory=RewardsCfg)
    init_state: InitStateCfg = field(default_factory=InitStateCfg)
    push: PushCfg = field(default_factory=PushCfg)
    domain_rand: DomainRandCfg = field(default_factory=DomainRandCfg)

    def second_stages(self) -> list[tuple[int, str]]:
        """(start step, what changes) for each curriculum stage that is set; tasks add their own."""
        stage = self.rewards.second_stage
        if not stage.start_step:
            return []
        changes = [f"{name} {weight:g}" for name, weight in stage.weights.items()]
        changes += [f"{stage.tracking_error} tracking errors"] if stage.tracking_error else []
        return [(stage.start_step, f"rewards: {', '.join(changes) or 'no change'}")]

    def validate(self) -> None:
        """Raise a one-line ConfigError for the first value outside its RULES (or not finite)."""
        check_values(self, self.RULES)
        unknown = [name for name in self.rewards.second_stage.weights if name not in self.rewards.weights]
        if unknown:
            raise ConfigError(
                f"config key 'rewards.second_stage.weights.{unknown[0]}' names no entry of rewards.weights; "
                f"allowed: {', '.join(self.rewards.weights)}"
            )
