"""mini_cheetah_osc: the Mini Cheetah with one decentralised phase oscillator per leg (the paper's task).

Each oscillator is driven by its own foot's normalised ground reaction force and integrated at
every physics substep with that substep's force. The ORC string switches the phase observations,
the phase rewards and the coupling; see gym_envs/orc.py.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import torch

from gym_envs import oscillators
from gym_envs.config import Check, OneOf, Range
from gym_envs.legged_robot_config import (
    NON_NEGATIVE,
    SHARE,
    CommandsCfg,
    ControlCfg,
    DomainRandCfg,
    EnvCfg,
    InitStateCfg,
    ObservationsCfg,
    PushCfg,
    RewardsCfg,
)
from gym_envs.mini_cheetah import PROPRIOCEPTION, MiniCheetah, MiniCheetahCfg
from gym_envs.orc import ORC_FORMAT, is_orc_string, parse_orc

OSCILLATOR_OBSERVATIONS = ("oscillator_obs", "oscillators_vel")
PHASE_REWARDS = ("swing_grf", "stance_grf", "swing_contact")
UNCOUPLED_COMMANDS = ("any", "straight")
SWING_CONTACT_FORCE = 0.1  # [body weights] a foot carrying more is in contact (the gait analysis's threshold)
GAIT_WEIGHTS = (
    NON_NEGATIVE,
    Check(lambda w: not w or (len(w) == len(oscillators.GAIT_NAMES) and sum(w) > 0),
          f"empty (uniform) or {len(oscillators.GAIT_NAMES)} weights for "
          f"{', '.join(oscillators.GAIT_NAMES)} with a positive sum"),
)


@dataclass
class OscillatorStageCfg:
    """The uncoupled episodes' settings from `start_step` control steps on (counted like
    rewards.second_stage.start_step): e.g. more sigma = 0 episodes, weighted to the rarely held gaits,
    only once the robots walk (docs/recipe-study.md, E36-E39). Both values replace the first stage's."""

    start_step: int = 0  # 0: no second stage
    coupling_off_prob: float = 0.0
    uncoupled_gait_weights: tuple[float, ...] = ()


@dataclass
class OscillatorCfg:
    orc: str = "111"
    init: str = "random"  # one of gym_envs.oscillators.PHASE_INIT_MODES
    process_noise_std: float = 0.25  # [Hz] per leg and substep (released code; not in the paper)
    omega_noise_std: float = 0.25  # training jitter of omega, redrawn every control step
    coupling_noise_std: float = 0.25
    coupling_max: float = 1.0  # sigma while moving
    # Share of training episodes run with sigma = 0 throughout (standing too): those robots keep
    # whatever phase offsets they start with, so the policy keeps seeing every relative phase.
    coupling_off_prob: float = 0.0
    # How those episodes start their oscillators ('any_gait': one of the four ideal gaits, so the rarely
    # held ones, pace above all, get a fair share of the uncoupled data); coupled episodes use `init`.
    uncoupled_init: str = "random"
    # With 'any_gait': relative weights of trot, pace, bound, pronk (oscillators.GAIT_NAMES); empty draws
    # them uniformly. Coupled episodes mostly trot already, so a weight moves data to the gaits seldom held.
    uncoupled_gait_weights: tuple[float, ...] = ()
    # The commands of those episodes: 'any' as drawn for every episode; 'straight' without the lateral
    # and yaw components, so that the started gaits are walked where obedience is asked of them
    # (straight ahead) instead of mostly while turning or side-stepping (docs/recipe-study.md, E46).
    uncoupled_commands: str = "any"
    stand_threshold: float = 0.5  # a standing speed (standing_rule) below this uses the standing parameters
    standing_rule: str = "lin_vel_x"  # one of gym_envs.oscillators.STANDING_RULES
    # Pay the phase rewards at a standing command too (the released code). Off, a robot told to stand has
    # no reward for stepping: with C = 0 its oscillators keep turning from their random start while it
    # stands, and the phase rewards would pay it to step in place in that pattern (docs/recipe-study.md).
    phase_rewards_standing: bool = True
    # Quirk switches of the released code, off by default:
    hold_grf: bool = False  # integrate all substeps with the previous control step's last force
    grf_normaliser_mass: float = 0.0  # [kg]; 0 uses the model's mass (8.952), the release used 8.292
    second_stage: OscillatorStageCfg = field(default_factory=OscillatorStageCfg)


@dataclass
class MiniCheetahOscCfg(MiniCheetahCfg):
    RULES: ClassVar[dict] = {
        **MiniCheetahCfg.RULES,
        "osc.orc": Check(is_orc_string, ORC_FORMAT),
        "osc.init": OneOf(oscillators.PHASE_INIT_MODES),
        "osc.process_noise_std": NON_NEGATIVE,
        "osc.omega_noise_std": NON_NEGATIVE,
        "osc.coupling_noise_std": NON_NEGATIVE,
        "osc.coupling_max": NON_NEGATIVE,
        "osc.coupling_off_prob": SHARE,
        "osc.uncoupled_init": OneOf(oscillators.PHASE_INIT_MODES),
        "osc.uncoupled_gait_weights": GAIT_WEIGHTS,
        "osc.uncoupled_commands": OneOf(UNCOUPLED_COMMANDS),
        "osc.second_stage.start_step": Range(0),
        "osc.second_stage.coupling_off_prob": SHARE,
        "osc.second_stage.uncoupled_gait_weights": GAIT_WEIGHTS,
        "osc.stand_threshold": NON_NEGATIVE,
        "osc.standing_rule": OneOf(oscillators.STANDING_RULES),
        "osc.grf_normaliser_mass": NON_NEGATIVE,
    }
    env: EnvCfg = field(default_factory=lambda: EnvCfg(episode_length_s=4.0))
    control: ControlCfg = field(default_factory=lambda: ControlCfg(action_scale=(0.2, 0.3, 0.3)))
    commands: CommandsCfg = field(
        default_factory=lambda: CommandsCfg(
            resampling_time_s=3.0,
            lin_vel_x_choices=(-3.0, -1.0, 0.0, 1.0, 3.0),
            lin_vel_x_noise=1.0,
            lin_vel_y=(-1.0, 1.0),
            yaw_rate=(-3.0, 3.0),
            zero_lateral_and_yaw_prob=0.2,
            zero_planar_prob=0.2,
            zero_all_prob=0.1,
        )
    )
    observations: ObservationsCfg = field(
        default_factory=lambda: ObservationsCfg(
            actor=PROPRIOCEPTION + ("oscillator_obs", "dof_pos_target"),
            critic=("base_height", "base_lin_vel")
            + PROPRIOCEPTION
            + ("oscillator_obs", "oscillators_vel", "dof_pos_target"),
            scales={
                "base_height": (0.3,),
                "base_lin_vel": (0.33,),
                "base_ang_vel": (0.3, 0.3, 0.1),
                "commands": (3.0, 1.0, 3.0),
                "dof_pos_obs": (0.2, 0.3, 0.3),
                "dof_vel": (2.0, 2.0, 4.0),
                "dof_pos_target": (0.2, 0.3, 0.3),
            },
            # Projected gravity gets no noise, as in the released code.
            noise={"base_ang_vel": (0.01,), "dof_pos_obs": (0.01,), "dof_vel": (0.005,)},
        )
    )
    rewards: RewardsCfg = field(
        default_factory=lambda: RewardsCfg(
            weights={
                "tracking_lin_vel": 4.0,
                "tracking_ang_vel": 2.0,
                "orientation": 1.0,
                "min_base_height": 1.5,
                "torques": 5e-7,
                "action_rate": 0.01,
                "action_rate2": 0.001,
                "cursorial": 0.25,
                "swing_grf": 5.0,
                "stance_grf": 5.0,
                "swing_contact": 0.0,  # not in the paper; the envelope recipe's second stage (E47)
            },
            termination_penalty=0.15,
            base_height_target=0.36,
        )
    )
    init_state: InitStateCfg = field(
        default_factory=lambda: InitStateCfg(
            mode="range",
            base_height=0.35,
            lin_vel_x=(-0.5, 2.0),
            lin_vel_z=(-0.05, 0.05),
            haa_noise=1e-5,
            timeout_reset_ratio=0.75,
        )
    )
    push: PushCfg = field(default_factory=lambda: PushCfg(enabled=True, interval_s=10.0, max_vel_xy=0.2))
    domain_rand: DomainRandCfg = field(
        default_factory=lambda: DomainRandCfg(randomize_friction=True, friction_range=(0.4, 1.0))
    )
    osc: OscillatorCfg = field(default_factory=OscillatorCfg)

    def second_stages(self) -> list[tuple[int, str]]:
        stage = self.osc.second_stage
        if not stage.start_step:
            return super().second_stages()
        weights = f", gait weights {list(stage.uncoupled_gait_weights)}" if stage.uncoupled_gait_weights else ""
        return super().second_stages() + [
            (stage.start_step, f"oscillators: {stage.coupling_off_prob:g} of the episodes uncoupled{weights}")]


def apply_orc(cfg: MiniCheetahOscCfg) -> MiniCheetahOscCfg:
    """Make the observation groups and reward weights say what cfg.osc.orc says (in place)."""
    orc = parse_orc(cfg.osc.orc)
    obs = cfg.observations
    if not orc.observations:
        obs.actor = tuple(t for t in obs.actor if t not in OSCILLATOR_OBSERVATIONS)
        obs.critic = tuple(t for t in obs.critic if t not in OSCILLATOR_OBSERVATIONS)
    if not orc.rewards:
        for weights in (cfg.rewards.weights, cfg.rewards.second_stage.weights):
            for name in PHASE_REWARDS:
                if name in weights:
                    weights[name] = 0.0
    return cfg


class MiniCheetahOsc(MiniCheetah):
    cfg: MiniCheetahOscCfg
    # The oscillators are per leg and identical, so mirroring swaps them like the feet.
    OBS_MIRROR: ClassVar[dict[str, str]] = {**MiniCheetah.OBS_MIRROR, "oscillator_obs": "legs", "oscillators_vel": "legs"}
    PER_ROBOT_DRAWN_TERMS: ClassVar[frozenset[str]] = frozenset(OSCILLATOR_OBSERVATIONS)  # the initial phases

    def __init__(self, cfg: MiniCheetahOscCfg):
        self.orc = parse_orc(cfg.osc.orc)
        super().__init__(cfg)

    def _init_timing(self) -> None:
        apply_orc(self.cfg)  # on the task's own copy, before the reward and observation terms are resolved
        super()._init_timing()

    def _init_buffers(self) -> None:
        super()._init_buffers()
        n, dev = self.num_envs, self.device
        mass = self.cfg.osc.grf_normaliser_mass or self.sim.robot_mass
        self.grf_normaliser = mass * self.sim.gravity
        self.phase = torch.zeros(n, self.num_legs, device=dev)
        self.phase_vel = torch.zeros(n, self.num_legs, device=dev)
        self.grf = torch.zeros(n, self.num_legs, device=dev)  # normalised GRF after the last substep
        self.omega = torch.zeros(n, 1, device=dev)
        self.coupling = torch.zeros(n, 1, device=dev)
        self.offset = torch.zeros(n, 1, device=dev)
        self.coupling_on = torch.ones(n, 1, device=dev)  # 0 for episodes drawn with sigma = 0
        # The uncoupled episodes' share and gait weights of the current stage (osc.second_stage).
        self.coupling_off_prob = self.cfg.osc.coupling_off_prob
        self.uncoupled_gait_weights = self.cfg.osc.uncoupled_gait_weights
        self.osc_stage = 1

    def _update_stages(self) -> None:
        super()._update_stages()
        stage = self.cfg.osc.second_stage
        if self.osc_stage == 1 and stage.start_step and self.common_step_counter >= stage.start_step:
            self.coupling_off_prob, self.uncoupled_gait_weights = stage.coupling_off_prob, stage.uncoupled_gait_weights
            self.osc_stage = 2

    def _pre_physics_step(self) -> None:
        osc = self.cfg.osc
        self.omega, self.coupling, self.offset = oscillators.oscillator_params(
            self.commands[:, 0],
            coupling_max=osc.coupling_max,
            stand_threshold=osc.stand_threshold,
            omega_noise_std=osc.omega_noise_std,
            coupling_noise_std=osc.coupling_noise_std,
            generator=self.generator,
            coupling_enabled=self.orc.coupling,
            stand_speed=oscillators.standing_speed(self.commands, osc.standing_rule),
        )
        self.coupling = self.coupling * self.coupling_on

    def _after_physics(self) -> None:
        grf = torch.clamp(self.foot_forces / self.grf_normaliser, 0.0, 1.0)  # (N, substeps, legs)
        drive = self.grf.unsqueeze(1).expand_as(grf) if self.cfg.osc.hold_grf else grf
        self.phase, self.phase_vel = oscillators.integrate_phases(
            self.phase, drive, self.omega, self.coupling, self.offset, self.physics_dt,
            process_noise_std=self.cfg.osc.process_noise_std, generator=self.generator,
        )
        self.grf = grf[:, -1]

    def _reset_task_state(self, env_ids: torch.Tensor) -> None:
        self.phase[env_ids] = oscillators.initial_phases(
            len(env_ids), self.cfg.osc.init, generator=self.generator, device=self.device
        )
        self.phase_vel[env_ids] = 0.0
        self.grf[env_ids] = 0.0
        if self.coupling_off_prob == 0.0:
            self.coupling_on[env_ids] = 1.0
        else:
            draw = torch.rand(len(env_ids), 1, generator=self.generator, device=self.device)
            self.coupling_on[env_ids] = (draw >= self.coupling_off_prob).float()
            if self.cfg.osc.uncoupled_init != self.cfg.osc.init:
                uncoupled = env_ids[self.coupling_on[env_ids, 0] == 0.0]
                self.phase[uncoupled] = oscillators.initial_phases(
                    len(uncoupled), self.cfg.osc.uncoupled_init, generator=self.generator, device=self.device,
                    gait_weights=self.uncoupled_gait_weights or None,
                )
        if self.cfg.osc.uncoupled_commands == "straight":
            # The reset's commands were drawn before the coupling draw, under the last episode's coupling.
            self._resample_commands(env_ids)

    def _resample_commands(self, env_ids: torch.Tensor) -> None:
        super()._resample_commands(env_ids)
        if self.cfg.osc.uncoupled_commands == "straight":
            uncoupled = env_ids[self.coupling_on[env_ids, 0] == 0.0]
            self.commands[uncoupled, 1:] = 0.0

    def _log_episodes(self, env_ids: torch.Tensor) -> None:
        super()._log_episodes(env_ids)
        # Which relative phases the moving robots' oscillators hold right now: if coupling pulls every
        # robot into one pattern, the policy never sees (and never learns to follow) the others.
        # Counted on the device (no host sync); a step with no robot moving logs zeros.
        moving = self._moving_command().float()
        labels, _ = oscillators.classify_rpd(oscillators.relative_phases(self.phase))
        counts = torch.zeros(len(oscillators.GAIT_NAMES) + 1, device=self.device).index_add_(0, labels, moving)
        shares = counts / moving.sum().clamp(min=1.0)
        for name, share in zip(oscillators.GAIT_NAMES + ("transition",), shares):
            self.extras["log"][f"Oscillator_gait/{name}"] = share

    # observations: cos block then sin block, as in the released code
    def _obs_oscillator_obs(self):
        return torch.cat([torch.cos(self.phase), torch.sin(self.phase)], dim=1)

    def _obs_oscillators_vel(self):
        return self.phase_vel

    def _moving_command(self) -> torch.Tensor:
        """(N,) bool: the command is not a standing one under osc.standing_rule and osc.stand_threshold."""
        speed = oscillators.standing_speed(self.commands, self.cfg.osc.standing_rule)
        return speed >= self.cfg.osc.stand_threshold

    # phase rewards: [0, pi) is swing (contact penalised), [pi, 2 pi) stance (contact rewarded)
    def _phase_reward_sin(self) -> torch.Tensor:
        """(N, legs) sin(phase), zero for robots at a standing command where osc.phase_rewards_standing is off."""
        sin = torch.sin(self.phase)
        if self.cfg.osc.phase_rewards_standing:
            return sin
        return sin * self._moving_command().unsqueeze(1)

    def _reward_swing_grf(self):
        return -torch.sum(torch.clamp(self._phase_reward_sin(), min=0.0) * self.grf, dim=1)

    def _reward_stance_grf(self):
        return torch.sum(torch.clamp(-self._phase_reward_sin(), min=0.0) * self.grf, dim=1)

    def _reward_swing_contact(self):
        # Each foot in contact during its swing half, whatever its force: a light extra step costs as
        # much as a heavy one, where swing_grf charges it by its small force (docs/recipe-study.md, E47).
        contact = (self.grf > SWING_CONTACT_FORCE).float()
        return -torch.sum(torch.clamp(self._phase_reward_sin(), min=0.0) * contact, dim=1)
