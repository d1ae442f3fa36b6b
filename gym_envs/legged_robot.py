"""LeggedRobot: the batched MDP shared by the legged tasks, on top of a physics backend.

One control step: actions -> joint targets -> `decimation` physics substeps -> state update ->
command resampling and pushes -> terminations and time-outs -> rewards -> resets -> observations.
Rewards are computed before the reset (they describe the step that was taken) and observations
after it (the first observation of a new episode is its own, not a mix of old and new state).

Reward terms are methods `_reward_<name>` weighted by `cfg.rewards.weights[name]`; observation
terms are methods `_obs_<name>`. Adding either is one method and one config entry.
"""

from __future__ import annotations

import copy
import math
from typing import ClassVar

import torch
from tensordict import TensorDict

from gym_envs import mirror
from gym_envs.config import ConfigError
from gym_envs.legged_robot_config import CommandsCfg, LeggedRobotCfg, model_file
from gym_envs.sim import SimBackend, SimState, make_backend


def quat_rotate_inverse(quat: torch.Tensor, vec: torch.Tensor) -> torch.Tensor:
    """Rotate world-frame vectors into the frame of the (w, x, y, z) quaternions."""
    w, xyz = quat[:, :1], quat[:, 1:]
    t = 2.0 * torch.cross(xyz, vec, dim=-1)
    return vec - w * t + torch.cross(xyz, t, dim=-1)


def _uniform(low, high, shape, generator, device) -> torch.Tensor:
    return low + (high - low) * torch.rand(shape, generator=generator, device=device)


def sample_commands(c: CommandsCfg, n: int, generator: torch.Generator, device) -> torch.Tensor:
    """Draw n commands (v_x, v_y, yaw rate) as the config says, zeroing masks included."""
    cmd = torch.empty(n, 3, device=device)
    if c.lin_vel_x_choices:
        choices = torch.tensor(c.lin_vel_x_choices, device=device)
        picks = choices[torch.randint(0, len(choices), (n,), generator=generator, device=device)]
        cmd[:, 0] = picks + c.lin_vel_x_noise * torch.randn(n, generator=generator, device=device)
    else:
        cmd[:, 0] = _uniform(*c.lin_vel_x, (n,), generator, device)
    cmd[:, 1] = _uniform(*c.lin_vel_y, (n,), generator, device)
    cmd[:, 2] = _uniform(*c.yaw_rate, (n,), generator, device)
    if c.small_command_norm > 0:
        cmd[:, :2] *= (torch.norm(cmd[:, :2], dim=1, keepdim=True) > c.small_command_norm).float()
    masks = ((c.zero_lateral_and_yaw_prob, (1, 2)), (c.zero_planar_prob, (0, 1)), (c.zero_all_prob, (0, 1, 2)))
    for prob, cols in masks:
        if prob > 0:
            keep = (torch.rand(n, 1, generator=generator, device=device) >= prob).float()
            cmd[:, list(cols)] *= keep
    return cmd


class LeggedRobot:
    cfg: LeggedRobotCfg
    # How each observation term changes under the left-right mirror (a kind of gym_envs.mirror.term_map).
    OBS_MIRROR: ClassVar[dict[str, str]] = {
        "base_height": "even",
        "base_lin_vel": "vector",
        "base_ang_vel": "axial",
        "projected_gravity": "vector",
        "commands": "command",
        "dof_pos_obs": "joints",
        "dof_vel": "joints",
        "dof_pos_target": "joints",
    }
    # Actor terms whose values are drawn per robot even when the robots start alike (a task's own state).
    PER_ROBOT_DRAWN_TERMS: ClassVar[frozenset[str]] = frozenset()

    def __init__(self, cfg: LeggedRobotCfg):
        cfg.validate()  # before anything is built
        self.cfg = cfg = copy.deepcopy(cfg)  # tasks adjust their copy (ORC); the caller's stays as given
        self.device = torch.device(cfg.env.device)
        self.num_envs = cfg.env.num_envs
        self.generator = torch.Generator(device=self.device).manual_seed(cfg.env.seed)
        self.sim: SimBackend = make_backend(
            cfg.sim.backend,
            model_path=model_file(cfg.sim.model_path),
            num_envs=self.num_envs,
            foot_sensors=tuple(cfg.sim.foot_sensors),
            termination_sensors=tuple(cfg.sim.termination_sensors),
            device=self.device,
            num_threads=cfg.sim.num_threads,
            cuda_graphs=cfg.sim.cuda_graphs,
        )
        self._init_timing()
        self._init_buffers()
        self._init_reward_terms()
        self._init_observation_terms()
        self._init_domain_randomisation()
        self.reset()

    def robots_indistinguishable(self) -> bool:
        """Whether the policy cannot tell this env's robots apart: they start alike (the default reset, no
        randomisation, no random pushes, no per-robot command draws) and the actor sees no noise and no
        per-robot draw. Given the same command and pushes, a deterministic policy then moves every robot
        alike, so the robots are one sample repeated; in floating point their records still part, because
        a batch's rows can round differently in the last bit (vector and scalar loops) and contact dynamics
        amplify that."""
        cfg = self.cfg
        dr, cmd, obs = cfg.domain_rand, cfg.commands, cfg.observations
        starts_alike = cfg.init_state.mode == "default" and not (
            dr.randomize_friction or dr.randomize_base_mass or dr.randomize_base_com or cfg.push.enabled
        )
        commands_alike = (
            len(set(cmd.lin_vel_x_choices)) <= 1 and cmd.lin_vel_x_noise == 0.0
            and all(low == high for low, high in (cmd.lin_vel_x, cmd.lin_vel_y, cmd.yaw_rate))
            and cmd.zero_lateral_and_yaw_prob == cmd.zero_planar_prob == cmd.zero_all_prob == 0.0
        )
        actor_noise = obs.noise_scale > 0 and any(name in obs.noise for name in obs.actor)
        draws_seen = any(name in self.PER_ROBOT_DRAWN_TERMS for name in obs.actor)
        return starts_alike and commands_alike and not actor_noise and not draws_seen

    # --- set-up ---------------------------------------------------------------------------------

    def _init_timing(self) -> None:
        cfg = self.cfg
        self.physics_dt = self.sim.timestep  # from the model, never assumed
        self.decimation = round(1.0 / (cfg.control.frequency_hz * self.physics_dt))
        if self.decimation < 1 or not math.isclose(self.decimation * self.physics_dt * cfg.control.frequency_hz, 1.0):
            raise ConfigError(
                f"control.frequency_hz={cfg.control.frequency_hz} is not a whole fraction of the model's "
                f"physics rate {1 / self.physics_dt:g} Hz; choose a divisor of it"
            )
        self.dt = self.decimation * self.physics_dt
        self.max_episode_length = math.ceil(cfg.env.episode_length_s / self.dt)
        self.resample_interval = max(1, round(cfg.commands.resampling_time_s / self.dt))
        self.push_interval = max(1, math.ceil(cfg.push.interval_s / self.dt))

    def _init_buffers(self) -> None:
        n, dev = self.num_envs, self.device
        self.num_actions = self.sim.num_joints
        self.num_legs = len(self.sim.foot_names)
        self.default_joint_pos = self.sim.default_joint_pos.to(dev)
        self.action_scale = self._per_joint(self.cfg.control.action_scale, "control.action_scale")
        self.actions = torch.zeros(n, self.num_actions, device=dev)
        # Joint-target offsets [rad] of this step and the two before (for the smoothness terms).
        self.target_history = torch.zeros(3, n, self.num_actions, device=dev)
        self.commands = torch.zeros(n, 3, device=dev)
        self.episode_length_buf = torch.zeros(n, dtype=torch.long, device=dev)
        self.common_step_counter = 0
        self.terminated = torch.zeros(n, dtype=torch.bool, device=dev)
        self.time_outs = torch.zeros(n, dtype=torch.bool, device=dev)
        self.foot_forces = torch.zeros(n, self.decimation, self.num_legs, device=dev)
        self.joint_torques = torch.zeros(n, self.decimation, self.num_actions, device=dev)
        self.gravity_vec = torch.tensor([0.0, 0.0, -1.0], device=dev).expand(n, 3)
        self.extras: dict = {}
        self._update_state(self.sim.read_state())

    def continue_from_step(self, step: int) -> None:
        """Continue a run whose policy has trained `step` control steps per env: the step counter (push
        timing, reward stage) resumes there instead of at 0."""
        self.common_step_counter = step
        self._update_stages()

    def _update_stages(self) -> None:
        """Switch to the second stage of each curriculum whose start step has come (tasks add their own)."""
        stage = self.cfg.rewards.second_stage
        if self.reward_stage == 1 and stage.start_step and self.common_step_counter >= stage.start_step:
            self.reward_weights.update(stage.weights)
            self.tracking_error_form = stage.tracking_error or self.tracking_error_form
            self.reward_stage = 2

    def _per_joint(self, values, name: str) -> torch.Tensor:
        """Expand one value, one per joint of a leg, or one per joint, to (num_joints,)."""
        v = torch.as_tensor(values, dtype=torch.float32, device=self.device).flatten()
        j, per_leg = self.num_actions, self.num_actions // self.num_legs
        if v.numel() in (1, j):
            return v.expand(j).clone()
        if v.numel() == per_leg:
            return v.repeat(self.num_legs)
        raise ConfigError(f"{name} has {v.numel()} values; give 1, one per joint of a leg ({per_leg}), or {j}")

    def _init_reward_terms(self) -> None:
        rewards = self.cfg.rewards
        later = rewards.second_stage.weights if rewards.second_stage.start_step else {}
        # A term weighted in either stage is resolved now, so that the switch builds nothing.
        self.reward_weights = {k: w for k, w in rewards.weights.items() if w != 0.0 or later.get(k, 0.0) != 0.0}
        self.reward_functions = {name: self._term("reward", name, "rewards.weights has")
                                 for name in self.reward_weights}
        self.tracking_error_form = rewards.tracking_error
        self.reward_stage = 1
        self.episode_sums = {name: torch.zeros(self.num_envs, device=self.device) for name in self.reward_weights}
        self.reward_terms = {name: torch.zeros(self.num_envs, device=self.device) for name in self.reward_weights}
        self.tracking_error_sum = torch.zeros(self.num_envs, device=self.device)  # of |command_xy - v_xy| [m/s]

    def _init_observation_terms(self) -> None:
        obs = self.cfg.observations
        for group in ("actor", "critic"):
            for name in getattr(obs, group):
                self._term("obs", name, f"observations.{group} lists")
        for table in ("scales", "noise"):
            for name in getattr(obs, table):
                if name not in obs.actor and name not in obs.critic:
                    raise ConfigError(f"observations.{table} has {name!r}, which no observation group uses")
        # Scale and noise vectors are sized on first use, from each term's actual width.
        self._obs_scale: dict[str, torch.Tensor] = {}
        self._obs_noise: dict[str, torch.Tensor] = {}

    def _term(self, kind: str, name: str, listed_in: str):
        """The term method `_<kind>_<name>`, or a ConfigError naming the terms there are."""
        method = getattr(self, f"_{kind}_{name}", None)
        if method is None:
            known = sorted(a[len(kind) + 2 :] for a in dir(self) if a.startswith(f"_{kind}_"))
            raise ConfigError(f"{listed_in} {name!r} but {type(self).__name__} has no _{kind}_{name}; "
                              f"known terms: {', '.join(known)}")
        return method

    def _init_domain_randomisation(self) -> None:
        dr, n, gen, dev = self.cfg.domain_rand, self.num_envs, self.generator, self.device
        all_ids = torch.arange(n, device=dev)
        if dr.randomize_friction:
            buckets = _uniform(*dr.friction_range, (dr.friction_buckets,), gen, dev)
            robot_friction = buckets[torch.randint(0, dr.friction_buckets, (n,), generator=gen, device=dev)]
            self.friction = 0.5 * (robot_friction + dr.ground_friction)
            self.sim.set_ground_friction(all_ids, self.friction)
        if dr.randomize_base_mass:
            self.sim.set_base_mass_offset(all_ids, _uniform(*dr.added_mass_range, (n,), gen, dev))
        if dr.randomize_base_com:
            low = torch.tensor([r[0] for r in dr.com_offset_range], device=dev)
            high = torch.tensor([r[1] for r in dr.com_offset_range], device=dev)
            self.sim.set_base_com_offset(all_ids, _uniform(low, high, (n, 3), gen, dev))

    # --- the control step -----------------------------------------------------------------------

    def step(self, actions: torch.Tensor):
        clip = self.cfg.control.clip_actions
        self.actions = torch.clamp(actions.to(self.device), -clip, clip)
        self.target_history = torch.roll(self.target_history, 1, dims=0)
        self.target_history[0] = self.actions * self.action_scale
        self._pre_physics_step()
        result = self.sim.step(self.default_joint_pos + self.target_history[0], self.decimation)
        self.foot_forces, self.joint_torques = result.foot_forces, result.joint_torques
        self._post_physics_step(result.state, result.diverged)
        return self.get_observations(), self.rew_buf, self.reset_buf, self.extras

    def _pre_physics_step(self) -> None:
        """Hook for tasks: runs after the targets are set, before the physics substeps."""

    def _post_physics_step(self, state: SimState, diverged: torch.Tensor) -> None:
        self.episode_length_buf += 1
        self.common_step_counter += 1
        self._update_stages()
        self._update_state(state)
        self._after_physics()
        # Index lists (a host sync each on CUDA) only where they size random draws: a draw per chosen
        # env keeps the random stream, and with it every seeded run, what it was.
        resample = (self.episode_length_buf % self.resample_interval == 0).nonzero().flatten()
        self._resample_commands(resample)
        if self.cfg.push.enabled and self.common_step_counter % self.push_interval == 0:
            self._push_robots()
        self.terminated = (state.termination_force > self.cfg.sim.termination_force) | diverged
        self.time_outs = self.episode_length_buf > self.max_episode_length
        self.reset_buf = self.terminated | self.time_outs
        self._compute_reward()
        self.tracking_error_sum += torch.norm(self.commands[:, :2] - self.base_lin_vel[:, :2], dim=1)
        done_ids = self.reset_buf.nonzero().flatten()  # one list for the logs and the resets
        self._log_episodes(done_ids)
        self._reset_envs(done_ids, self.terminated, self.time_outs)

    def _after_physics(self) -> None:
        """Hook for tasks: state is current, rewards not yet computed (oscillators integrate here)."""

    def _update_state(self, state: SimState) -> None:
        self.state = state
        self.base_lin_vel = quat_rotate_inverse(state.base_quat, state.base_lin_vel)
        self.base_ang_vel = state.base_ang_vel
        self.projected_gravity = quat_rotate_inverse(state.base_quat, self.gravity_vec)
        self.joint_pos, self.joint_vel = state.joint_pos, state.joint_vel

    def _push_robots(self) -> None:
        ids = torch.arange(self.num_envs, device=self.device)
        m = self.cfg.push.max_vel_xy
        self.sim.push_base(ids, _uniform(-m, m, (self.num_envs, 2), self.generator, self.device))

    # --- rewards --------------------------------------------------------------------------------

    def _compute_reward(self) -> None:
        self.rew_buf = torch.zeros(self.num_envs, device=self.device)
        alive = (~self.terminated).float()
        for name, fn in self.reward_functions.items():
            term = fn() * self.reward_weights[name] * self.dt * alive
            self.rew_buf += term
            self.episode_sums[name] += term
            self.reward_terms[name] = term  # this step's, for analysis: what a policy is paid for, term by term
        self.rew_buf -= self.cfg.rewards.termination_penalty * self.terminated.float()

    def _log_episodes(self, env_ids: torch.Tensor) -> None:
        log = {}
        if len(env_ids) > 0:
            seconds = self.episode_length_buf[env_ids].float().clamp(min=1) * self.dt
            for name, sums in self.episode_sums.items():
                log[f"Episode_Reward/{name}"] = torch.mean(sums[env_ids] / seconds)
                sums[env_ids] = 0.0
            log["Episode/terminated"] = self.terminated[env_ids].float().mean()
            steps = self.episode_length_buf[env_ids].float().clamp(min=1)
            log["Episode/tracking_error"] = torch.mean(self.tracking_error_sum[env_ids] / steps)
            self.tracking_error_sum[env_ids] = 0.0
        self.extras = {"time_outs": self.time_outs.clone(), "log": log}

    # --- resets ---------------------------------------------------------------------------------

    def reset(self):
        """Reset every env; returns the first observations."""
        everyone = torch.ones(self.num_envs, dtype=torch.bool, device=self.device)
        self._reset_envs(torch.arange(self.num_envs, device=self.device), everyone, torch.zeros_like(everyone))
        self.rew_buf = torch.zeros(self.num_envs, device=self.device)
        self.reset_buf = torch.zeros_like(everyone)
        return self.get_observations()

    def _reset_envs(self, env_ids: torch.Tensor, terminated: torch.Tensor, timed_out: torch.Tensor) -> None:
        """Envs env_ids (those terminated or timed out) start a new episode; terminated ones are
        re-initialised, and of the timed-out ones only a share (timeout_reset_ratio)."""
        if len(env_ids) == 0:
            return
        flagged = terminated | timed_out
        keep_going = timed_out & ~terminated
        keep_going &= torch.rand(self.num_envs, generator=self.generator, device=self.device) >= (
            self.cfg.init_state.timeout_reset_ratio
        )
        self._reset_robot_state((flagged & ~keep_going).nonzero().flatten())
        self._resample_commands(env_ids)
        self.target_history[:, env_ids] = 0.0
        self.episode_length_buf[env_ids] = 0
        self._reset_task_state(env_ids)

    def _reset_task_state(self, env_ids: torch.Tensor) -> None:
        """Hook for tasks: per-episode state of their own (oscillator phases)."""

    def _reset_robot_state(self, env_ids: torch.Tensor) -> None:
        n = len(env_ids)
        if n == 0:
            return
        init, gen, dev = self.cfg.init_state, self.generator, self.device
        base_pos = torch.zeros(n, 3, device=dev)
        base_pos[:, 2] = init.base_height
        quat = torch.zeros(n, 4, device=dev)
        quat[:, 0] = 1.0
        lin_vel = torch.zeros(n, 3, device=dev)
        joint_pos = self.default_joint_pos.expand(n, -1).clone()
        if init.mode == "range":
            for axis, rng in enumerate((init.lin_vel_x, init.lin_vel_y, init.lin_vel_z)):
                lin_vel[:, axis] = _uniform(*rng, (n,), gen, dev)
            haa = slice(0, self.num_actions, 3)
            joint_pos[:, haa] += _uniform(-init.haa_noise, init.haa_noise, (n, self.num_legs), gen, dev)
        elif init.mode != "default":
            raise ConfigError(f"init_state.mode={init.mode!r} is unknown; use 'range' or 'default'")
        zeros3 = torch.zeros(n, 3, device=dev)
        self.sim.reset(env_ids, base_pos, quat, lin_vel, zeros3, joint_pos, torch.zeros_like(joint_pos))
        self._update_state(self.sim.read_state())

    def _resample_commands(self, env_ids: torch.Tensor) -> None:
        if len(env_ids) > 0:
            self.commands[env_ids] = sample_commands(self.cfg.commands, len(env_ids), self.generator, self.device)

    # --- observations ---------------------------------------------------------------------------

    def get_observations(self) -> TensorDict:
        groups = {
            "actor": self._observation_group(self.cfg.observations.actor, noisy=True),
            "critic": self._observation_group(self.cfg.observations.critic, noisy=False),
        }
        return TensorDict(groups, batch_size=[self.num_envs], device=self.device)

    def _observation_group(self, names, noisy: bool) -> torch.Tensor:
        parts = []
        noise_scale = self.cfg.observations.noise_scale
        for name in names:
            value = getattr(self, f"_obs_{name}")()
            scale = self._term_vector(self._obs_scale, self.cfg.observations.scales, name, value.shape[1], 1.0)
            value = value / scale
            if noisy and noise_scale > 0 and name in self.cfg.observations.noise:
                half_width = self._term_vector(self._obs_noise, self.cfg.observations.noise, name, value.shape[1], 0.0)
                noise = 2.0 * torch.rand(value.shape, generator=self.generator, device=self.device) - 1.0
                value = value + noise * (half_width / scale) * noise_scale
            parts.append(value)
        return torch.cat(parts, dim=1)

    def observation_scales(self, group: str) -> dict[str, torch.Tensor]:
        """The terms of an observation group in order, each with its per-element scale (the term is divided by it)."""
        scales = {}
        for name in getattr(self.cfg.observations, group):
            width = getattr(self, f"_obs_{name}")().shape[1]
            scales[name] = self._term_vector(self._obs_scale, self.cfg.observations.scales, name, width, 1.0)
        return scales

    def mirror_maps(self) -> dict[str, tuple[torch.Tensor, torch.Tensor]]:
        """Left-right mirror maps, `(index, sign)` as in gym_envs.mirror, of the actions and of each
        observation group ('actions', 'actor', 'critic'), from the model's geometry."""
        joints = mirror.joint_map(self.sim.joint_anchors, self.sim.joint_axes, self.default_joint_pos.cpu().numpy())
        legs = mirror.leg_map(self.sim.foot_positions)
        maps = {"actions": joints}
        self._check_mirror_symmetric("control.action_scale", self.action_scale, joints[0])
        for group in ("actor", "critic"):
            parts = []
            for name, scale in self.observation_scales(group).items():
                if name not in self.OBS_MIRROR:
                    raise ConfigError(f"observation term {name!r} has no mirror rule; add it to "
                                      f"{type(self).__name__}.OBS_MIRROR (kinds: gym_envs.mirror.term_map)")
                parts.append(mirror.term_map(self.OBS_MIRROR[name], len(scale), joints, legs))
                self._check_mirror_symmetric(f"observations.scales[{name!r}]", scale, parts[-1][0])
            maps[group] = mirror.concatenate(parts)
        return {key: (torch.as_tensor(index, device=self.device), torch.as_tensor(sign, dtype=torch.float32,
                                                                                 device=self.device))
                for key, (index, sign) in maps.items()}

    @staticmethod
    def _check_mirror_symmetric(what: str, values: torch.Tensor, index) -> None:
        if not torch.equal(values[torch.as_tensor(index, device=values.device)], values):
            raise ConfigError(f"{what} differs between left and right; mirror augmentation needs it symmetric")

    def _term_vector(self, cache: dict, table: dict, name: str, width: int, default: float) -> torch.Tensor:
        vec = cache.get(name)
        if vec is None:
            values = torch.as_tensor(table.get(name, (default,)), dtype=torch.float32, device=self.device).flatten()
            if width % values.numel() != 0:
                raise ConfigError(f"observations entry {name!r} has {values.numel()} values for a term of width {width}")
            vec = cache[name] = values.repeat(width // values.numel())
        return vec

    def _obs_base_height(self):
        return self.state.base_pos[:, 2:3]

    def _obs_base_lin_vel(self):
        return self.base_lin_vel

    def _obs_base_ang_vel(self):
        return self.base_ang_vel

    def _obs_projected_gravity(self):
        return self.projected_gravity

    def _obs_commands(self):
        return self.commands

    def _obs_dof_pos_obs(self):
        return self.joint_pos - self.default_joint_pos

    def _obs_dof_vel(self):
        return self.joint_vel

    def _obs_dof_pos_target(self):
        return self.target_history[0]

    # --- reward terms shared by legged tasks ------------------------------------------------------

    def _reward_torques(self):
        return -torch.sum(self.joint_torques[:, -1] ** 2, dim=1)

    def _reward_action_rate(self):
        # Divided by (dt * decimation)^2 as in the released code (a constant factor on the weight).
        step = self.dt * self.decimation
        return -torch.sum((self.target_history[0] - self.target_history[1]) ** 2, dim=1) / step**2

    def _reward_action_rate2(self):
        step = self.dt * self.decimation
        h = self.target_history
        return -torch.sum((h[0] - 2.0 * h[1] + h[2]) ** 2, dim=1) / step**2

    def _reward_base_height(self):
        return -((self.state.base_pos[:, 2] - self.cfg.rewards.base_height_target) ** 2)
