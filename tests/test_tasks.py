"""The legged-robot MDP and the mini_cheetah_osc task: observations, rewards, commands, resets, ORC."""

import math
import warnings

import pytest
import torch

from gym_envs import ConfigError, UnknownTaskError, env_cfg_class, make_env, oscillators
from gym_envs.config import apply_overrides
from gym_envs.legged_robot import sample_commands
from gym_envs.mini_cheetah_osc import MiniCheetahOscCfg
from gym_envs.orc import parse_orc, parse_training_orc
from gym_envs.oscillators import TWO_PI


def osc_env(num_envs=4, overrides=(), **osc):
    cfg = MiniCheetahOscCfg()
    cfg.env.num_envs = num_envs
    cfg.sim.num_threads = 1
    for key, value in osc.items():
        setattr(cfg.osc, key, value)
    return make_env("mini_cheetah_osc", apply_overrides(cfg, list(overrides)))


def quiet_standing(num_envs=4, overrides_extra=(), **osc):
    """Standing command, no noise, jitter, pushes or command changes: the evaluation setting."""
    overrides = [*overrides_extra, 
        "observations.noise_scale=0", "osc.process_noise_std=0", "osc.omega_noise_std=0",
        "osc.coupling_noise_std=0", "push.enabled=false", "commands.resampling_time_s=1000",
        "env.episode_length_s=1000", "init_state.mode=default",
    ]
    env = osc_env(num_envs, overrides, **osc)
    env.commands[:] = 0.0
    return env


# --- observation sizes and the ORC switch ----------------------------------------------------------


@pytest.mark.parametrize(
    "orc, actor, critic",
    [("111", 53, 61), ("110", 53, 61), ("101", 53, 61), ("100", 53, 61), ("011", 45, 49), ("010", 45, 49), ("000", 45, 49)],
)
def test_observation_sizes_per_orc(orc, actor, critic):
    obs = osc_env(2, orc=orc).get_observations()
    assert obs["actor"].shape == (2, actor) and obs["critic"].shape == (2, critic)


def test_parent_task_observations():
    cfg = env_cfg_class("mini_cheetah")()
    cfg.env.num_envs = 2
    obs = make_env("mini_cheetah", cfg).get_observations()
    assert obs["actor"].shape == (2, 37) and obs["critic"].shape == (2, 37)


@pytest.mark.parametrize("text", ["11", "1111", "112", "abc", "", "1 1"])
def test_malformed_orc_is_an_error(text):
    with pytest.raises(ConfigError, match="malformed ORC string"):
        parse_orc(text)


def test_training_orc_001_says_it_equals_000_but_an_evaluation_that_couples_a_000_policy_is_quiet():
    with pytest.warns(UserWarning, match="001 equals 000"):
        assert parse_training_orc("001") == (False, False, True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        parse_training_orc("111")
        assert parse_orc("001") == (False, False, True)
        osc_env(2, orc="001")  # what analysis builds to run ORC-000 with sigma = 1


def test_orc_r0_removes_phase_rewards_only():
    env = osc_env(2, orc="101")
    assert "swing_grf" not in env.reward_functions and "stance_grf" not in env.reward_functions
    assert "tracking_lin_vel" in env.reward_functions
    assert "swing_grf" in osc_env(2, orc="111").reward_functions


def test_orc_c0_means_no_coupling_anywhere():
    env = osc_env(64, orc="110")  # training jitter stays on
    env.commands[:32, 0] = 0.0  # standing
    env.commands[32:, 0] = 2.0  # moving
    env._pre_physics_step()
    assert torch.all(env.coupling == 0.0)
    env = osc_env(64, orc="111")
    env.commands[:32, 0] = 0.0
    env._pre_physics_step()
    assert env.coupling[:32].mean() == pytest.approx(4.0, abs=0.2)


def test_coupling_off_share_of_episodes():
    env = osc_env(256, orc="111", coupling_off_prob=0.5)
    env.reset()
    off = env.coupling_on[:, 0] == 0.0
    assert 0.35 < off.float().mean() < 0.65  # drawn per episode
    env.commands[:128, 0] = 0.0  # standing ones too
    env.commands[128:, 0] = 1.0
    env._pre_physics_step()
    assert torch.all(env.coupling[off] == 0.0)
    assert torch.all(env.coupling[~off] > 0.0)
    first = env.coupling_on.clone()
    env._reset_task_state(torch.arange(256))
    assert not torch.equal(first, env.coupling_on)  # redrawn at every reset


def test_uncoupled_episodes_can_start_in_ideal_gaits_while_coupled_ones_keep_random_phases():
    env = osc_env(512, ["osc.uncoupled_init=any_gait"], orc="111", coupling_off_prob=0.5)
    env._reset_task_state(torch.arange(512))
    off = env.coupling_on[:, 0] == 0.0
    labels, _ = oscillators.classify_rpd(oscillators.relative_phases(env.phase))
    transition = len(oscillators.GAIT_NAMES)
    assert torch.all(labels[off] != transition)  # every uncoupled robot holds an ideal gait
    shares = torch.bincount(labels[off], minlength=transition + 1).float() / off.sum()
    assert shares[:transition].min() > 0.15  # all four, about a quarter each
    assert (labels[~off] == transition).float().mean() > 0.3  # uniform phases: about 46 % transition


def test_oscillator_gait_mix_is_logged():
    env = osc_env(16, ["osc.init=trot", "osc.process_noise_std=0"], orc="110")
    env.reset()
    env.commands[:, 0] = 1.0
    _, _, _, extras = env.step(torch.zeros(16, 12))
    log = extras["log"]
    assert log["Oscillator_gait/trot"] == pytest.approx(1.0)  # sigma = 0 keeps the started pattern
    assert sum(float(log[f"Oscillator_gait/{g}"]) for g in ("trot", "pace", "bound", "pronk", "transition")) == 1.0
    env.commands[8:, 0] = 0.0  # standing robots are left out of the shares
    env.phase[8:] = 1.5 * math.pi  # all legs in phase: pronk
    env._log_episodes(torch.arange(0))
    assert env.extras["log"]["Oscillator_gait/pronk"] == 0.0
    env.commands[:, 0] = 0.0  # nobody moving: counted on the device, so zeros rather than no entry
    env._log_episodes(torch.arange(0))
    assert all(float(share) == 0.0 for key, share in env.extras["log"].items() if key.startswith("Oscillator_gait/"))


def test_unknown_task_lists_the_known_ones():
    with pytest.raises(UnknownTaskError, match="unknown task 'mini_cheetah_os'; known tasks: mini_cheetah, mini_cheetah_osc"):
        make_env("mini_cheetah_os")


def test_unknown_reward_weight_is_an_error():
    cfg = MiniCheetahOscCfg()
    cfg.env.num_envs = 2
    cfg.rewards.weights["tracking_lin_velocity"] = 1.0
    with pytest.raises(ConfigError, match="no _reward_tracking_lin_velocity; known terms:.*tracking_lin_vel"):
        make_env("mini_cheetah_osc", cfg)


def test_unknown_observation_term_is_an_error():
    cfg = MiniCheetahOscCfg()
    cfg.env.num_envs = 2
    cfg.observations.actor = cfg.observations.actor + ("foot_height",)
    with pytest.raises(ConfigError, match="lists 'foot_height'"):
        make_env("mini_cheetah_osc", cfg)


def test_control_rate_must_divide_physics_rate():
    cfg = MiniCheetahOscCfg()
    cfg.env.num_envs = 2
    cfg.control.frequency_hz = 300.0
    with pytest.raises(ConfigError, match="control.frequency_hz=300"):
        make_env("mini_cheetah_osc", cfg)


# --- reward terms on hand-made states --------------------------------------------------------------


def test_phase_rewards_sign_and_scale():
    env = quiet_standing(2)
    env.phase[:] = torch.tensor([[0.5 * math.pi] * 4, [1.5 * math.pi] * 4])  # env 0 swing, env 1 stance
    env.grf[:] = 0.25
    assert env._reward_swing_grf().tolist() == pytest.approx([-1.0, 0.0])  # contact in swing penalised
    assert env._reward_stance_grf().tolist() == pytest.approx([0.0, 1.0])  # contact in stance rewarded
    env.grf[:] = 0.0
    assert env._reward_swing_grf().tolist() == pytest.approx([0.0, 0.0])


def test_phase_rewards_standing_off_leaves_standing_robots_unpaid():
    env = quiet_standing(2, overrides_extra=["osc.phase_rewards_standing=false", "rewards.weights.swing_contact=1.0"])
    env.commands[1, 0] = 1.0  # robot 0 told to stand, robot 1 to walk
    env.phase[:] = torch.tensor([[0.5 * math.pi] * 4, [0.5 * math.pi] * 4])  # both in swing, both loaded
    env.grf[:] = 0.25
    assert env._reward_swing_grf().tolist() == pytest.approx([0.0, -1.0])
    assert env._reward_swing_contact().tolist() == pytest.approx([0.0, -4.0])
    env.phase[:] = 1.5 * math.pi  # stance
    assert env._reward_stance_grf().tolist() == pytest.approx([0.0, 1.0])
    env.commands[0, 2] = 1.0  # a turn on the spot is moving under the 'command' rule, standing under |v_x|
    assert env._reward_stance_grf()[0] == pytest.approx(0.0)
    env.cfg.osc.standing_rule = "command"
    assert env._reward_stance_grf()[0] == pytest.approx(1.0)


def test_swing_contact_counts_swing_contacts_whatever_their_force():
    env = quiet_standing(3, overrides_extra=["rewards.weights.swing_contact=1.0"])
    env.phase[:] = torch.tensor([[0.5 * math.pi] * 4, [0.5 * math.pi] * 4, [1.5 * math.pi] * 4])
    env.grf[:] = torch.tensor([[0.15] * 4, [0.6] * 4, [0.6] * 4])  # light and heavy swing steps, then stance
    assert env._reward_swing_contact().tolist() == pytest.approx([-4.0, -4.0, 0.0])
    assert env._reward_swing_grf()[0] == pytest.approx(0.25 * env._reward_swing_grf()[1])  # the force-weighted term
    env.grf[:] = 0.05  # below the contact force: in the air
    assert env._reward_swing_contact().tolist() == pytest.approx([0.0, 0.0, 0.0])
    assert "swing_contact" not in osc_env(2, orc="101", overrides=["rewards.weights.swing_contact=1.0"]).reward_functions


def test_tracking_orientation_and_height_rewards():
    env = quiet_standing(2)
    env.commands[:] = torch.tensor([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    env.base_lin_vel = torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    track = env._reward_tracking_lin_vel()
    assert track[0] == pytest.approx(1.0) and track[1] == pytest.approx(math.exp(-(0.5**2) / 0.25))
    env.projected_gravity = torch.tensor([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    assert env._reward_orientation().tolist() == pytest.approx([2.0, 1.0 + math.exp(-4.0)])
    env.state.base_pos[:, 2] = torch.tensor([0.40, 0.06])
    assert env._reward_min_base_height().tolist() == pytest.approx([1.0, math.exp(-1.0 / 0.25)])


def test_yaw_tracking_pays_for_a_1_rad_s_error_unless_the_released_quartic_is_asked_for():
    def yaw_reward(form):
        env = quiet_standing(3, overrides_extra=[f"rewards.yaw_tracking={form}"])
        env.commands[:] = torch.tensor([[1.0, 0.0, 0.0], [1.0, 0.0, 1.0], [0.0, 0.0, 3.0]])
        env.base_ang_vel = torch.tensor([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
        return env._reward_tracking_ang_vel().tolist()
    # Relative to the command's size, like the linear term: exp(-(e / (1 + |c|))^2 / 0.25).
    assert yaw_reward("sqexp") == pytest.approx([1.0, math.exp(-(0.5**2) / 0.25), math.exp(-(0.75**2) / 0.25)])
    assert yaw_reward("sqexp")[2] > 0.1  # standing still under a 3 rad/s command still has a gradient
    quartic = yaw_reward("released_quartic")
    assert quartic[1] == pytest.approx(math.exp(-((1 / 5) ** 4) / 0.25)) and quartic[1] > 0.99


def test_absolute_tracking_errors_hold_a_fast_command_to_the_width_of_a_slow_one():
    def tracking(form):
        env = quiet_standing(2, overrides_extra=[f"rewards.tracking_error={form}"])
        env.commands[:] = torch.tensor([[1.0, 0.0, 1.0], [3.0, 0.0, 3.0]])
        env.base_lin_vel = torch.tensor([[0.7, 0.0, 0.0], [2.7, 0.0, 0.0]])  # 0.3 m/s short of each
        env.base_ang_vel = torch.tensor([[0.0, 0.0, 0.7], [0.0, 0.0, 2.7]])
        return env._reward_tracking_lin_vel().tolist(), env._reward_tracking_ang_vel().tolist()
    lin, yaw = tracking("relative")
    assert lin == pytest.approx([math.exp(-(0.15**2) / 0.25), math.exp(-(0.075**2) / 0.25)])
    assert yaw == pytest.approx(lin)
    lin, yaw = tracking("absolute")
    assert lin == pytest.approx([math.exp(-(0.3**2) / 0.25)] * 2) and yaw == pytest.approx(lin)


def test_the_oscillators_second_stage_changes_the_uncoupled_draws_from_its_step_on():
    stage = ["osc.coupling_off_prob=0.25", "osc.second_stage.start_step=2", "osc.second_stage.coupling_off_prob=1.0",
             "osc.uncoupled_init=any_gait", "osc.second_stage.uncoupled_gait_weights=[0.0, 0.0, 1.0, 0.0]"]
    env = quiet_standing(64, overrides_extra=stage)
    first_draw = env.coupling_on.clone()
    assert 0 < (first_draw == 0).sum().item() < 64  # a quarter uncoupled, started in any gait
    env.step(torch.zeros(64, env.num_actions))
    assert env.osc_stage == 1
    env.step(torch.zeros(64, env.num_actions))
    assert env.osc_stage == 2 and torch.equal(env.coupling_on, first_draw)  # draws change at resets only
    env.reset()
    labels, _ = oscillators.classify_rpd(oscillators.relative_phases(env.phase))
    assert (env.coupling_on == 0).all() and (labels == oscillators.GAIT_NAMES.index("bound")).all()
    assert "oscillators: 1 of the episodes uncoupled, gait weights [0.0, 0.0, 1.0, 0.0]" in [
        text for _, text in apply_overrides(MiniCheetahOscCfg(), stage).second_stages()]
    with pytest.raises(ConfigError, match="osc.second_stage.uncoupled_gait_weights"):
        apply_overrides(MiniCheetahOscCfg(), ["osc.second_stage.uncoupled_gait_weights=[1.0]"]).validate()


def test_uncoupled_episodes_walk_straight_when_asked_and_coupled_ones_keep_every_command():
    overrides = ["osc.coupling_off_prob=0.5", "commands.zero_lateral_and_yaw_prob=0", "commands.zero_planar_prob=0",
                 "commands.zero_all_prob=0", "commands.lin_vel_y=[0.2, 0.7]", "commands.yaw_rate=[0.5, 1.5]"]

    def lateral_and_yaw_by_coupling(env):
        on = env.coupling_on[:, 0] == 1.0
        return env.commands[on, 1:], env.commands[~on, 1:]

    env = osc_env(256, overrides + ["osc.uncoupled_commands=straight"])
    draws = []
    for refresh in (lambda: None, lambda: env._resample_commands(torch.arange(256)), env.reset, env.reset):
        refresh()  # the first reset's draw, a mid-episode resample, two more resets with new coupling draws
        coupled, uncoupled = lateral_and_yaw_by_coupling(env)
        assert len(coupled) > 64 and len(uncoupled) > 64
        assert (uncoupled == 0).all() and (coupled > 0).all()  # ranges exclude zero: nothing coupled was zeroed
        draws.append(env.coupling_on.clone())
    assert not torch.equal(draws[-1], draws[-2])  # robots changed coupling between the last two resets
    _, uncoupled = lateral_and_yaw_by_coupling(osc_env(256, overrides))  # the default: every command as drawn
    assert (uncoupled > 0).all()
    with pytest.raises(ConfigError, match="osc.uncoupled_commands"):
        apply_overrides(MiniCheetahOscCfg(), ["osc.uncoupled_commands=forward"]).validate()


def test_the_second_reward_stage_takes_over_at_its_step_and_obeys_the_orc():
    stage = ["rewards.second_stage.start_step=3", "rewards.second_stage.tracking_error=absolute",
             "rewards.second_stage.weights={swing_grf: 10.0, cursorial: 0.5}", "rewards.weights.cursorial=0.0"]
    env = quiet_standing(2, overrides_extra=stage)
    assert env.reward_weights["cursorial"] == 0.0 and "cursorial" in env.reward_functions  # resolved for stage 2
    for _ in range(2):
        env.step(torch.zeros(2, env.num_actions))
    assert (env.reward_stage, env.tracking_error_form, env.reward_weights["swing_grf"]) == (1, "relative", 5.0)
    env.step(torch.zeros(2, env.num_actions))
    assert (env.reward_stage, env.tracking_error_form) == (2, "absolute")
    assert (env.reward_weights["swing_grf"], env.reward_weights["cursorial"], env.reward_weights["stance_grf"]) == (10.0, 0.5, 5.0)
    without_phase_rewards = quiet_standing(2, overrides_extra=stage, orc="101")
    without_phase_rewards.continue_from_step(3)  # a resumed run enters the stage at once
    assert without_phase_rewards.reward_stage == 2 and without_phase_rewards.reward_weights["swing_grf"] == 0.0
    with pytest.raises(ConfigError, match=r"'rewards.second_stage.weights.swing' names no entry of rewards.weights"):
        apply_overrides(MiniCheetahOscCfg(), ["rewards.second_stage.weights={swing: 1.0}"]).validate()
    with pytest.raises(ConfigError, match="osc.uncoupled_gait_weights"):
        apply_overrides(MiniCheetahOscCfg(), ["osc.uncoupled_gait_weights=[1.0, 2.0]"]).validate()


def test_the_standing_schedule_reads_the_whole_command_when_asked():
    commands = torch.tensor([[0.0, 0.0, 0.0], [0.0, 0.0, -1.5], [0.0, 0.5, 0.0], [1.0, 0.0, 0.0]])
    for rule, standing in (("lin_vel_x", [True, True, True, False]), ("command", [True, False, False, False])):
        env = quiet_standing(4, overrides_extra=[f"osc.standing_rule={rule}"])
        env.commands[:] = commands
        env._pre_physics_step()
        assert (env.coupling[:, 0] == oscillators.STANDING_COUPLING).tolist() == standing, rule
        assert env.omega[1, 0] == pytest.approx(1.0 if rule == "lin_vel_x" else 1.5)  # turning on the spot: |v_x| + 1.5


def test_penalties_are_negative_and_scaled():
    env = quiet_standing(1)
    env.joint_torques = torch.zeros(1, env.decimation, 12)
    env.joint_torques[0, -1, 0] = 10.0
    assert env._reward_torques().item() == pytest.approx(-100.0)
    env.target_history[:] = 0.0
    env.target_history[0, 0, 0] = 0.05
    assert env._reward_action_rate().item() == pytest.approx(-1.0)  # (0.05 / 0.05)^2
    assert env._reward_action_rate2().item() == pytest.approx(-1.0)
    env.joint_pos = env.default_joint_pos.clone().unsqueeze(0)
    env.joint_pos[0, 0] = 0.2  # one abduction joint at 0.2 rad
    assert env._reward_cursorial().item() == pytest.approx(-0.25)


def test_step_reward_is_weighted_sum_times_dt():
    env = quiet_standing(2)
    env.step(torch.zeros(2, 12))
    expected = sum(fn() * env.reward_weights[name] * env.dt for name, fn in env.reward_functions.items())
    assert torch.allclose(env.rew_buf, expected)


# --- commands ----------------------------------------------------------------------------------------


def test_command_zeroing_rates_match_the_released_distribution():
    cmd = sample_commands(MiniCheetahOscCfg().commands, 200_000, torch.Generator().manual_seed(1), "cpu")
    nonzero = (cmd != 0).float().mean(dim=0)
    assert nonzero[0] == pytest.approx(0.72, abs=0.01)  # v_x survives 0.8 * 0.9
    assert nonzero[1] == pytest.approx(0.576, abs=0.01)  # v_y survives 0.8 * 0.8 * 0.9
    assert nonzero[2] == pytest.approx(0.72, abs=0.01)
    assert (cmd == 0).all(dim=1).float().mean() == pytest.approx(0.136, abs=0.01)
    assert (cmd[:, 0].abs() < 0.5).float().mean() == pytest.approx(0.41, abs=0.01)


def test_commands_resample_on_schedule():
    env = osc_env(8, ["push.enabled=false"])
    env.commands[:] = 99.0
    env.episode_length_buf[:] = torch.arange(8) + env.resample_interval - 4
    env.step(torch.zeros(8, 12))
    redrawn = (env.commands != 99.0).any(dim=1)
    assert redrawn.tolist() == [i == 3 for i in range(8)]  # only the env whose counter hit 300


# --- terminations, time-outs and resets ---------------------------------------------------------------


def test_timeouts_are_not_terminations():
    env = quiet_standing(4)
    env.step(torch.zeros(4, 12))
    env.episode_length_buf[:2] = env.max_episode_length
    _, _, dones, extras = env.step(torch.zeros(4, 12))
    assert dones.tolist() == [True, True, False, False]
    assert extras["time_outs"].tolist() == [True, True, False, False]
    assert not env.terminated.any()
    assert env.episode_length_buf[:2].tolist() == [0, 0]


def test_some_timed_out_robots_keep_their_state():
    env = quiet_standing(64)
    env.cfg.init_state.timeout_reset_ratio = 0.0  # keep all
    for _ in range(20):
        env.step(torch.zeros(64, 12))
    before = env.state.base_pos.clone()
    phases = env.phase.clone()
    env.episode_length_buf[:] = env.max_episode_length
    env.step(torch.zeros(64, 12))
    assert torch.allclose(env.state.base_pos, before, atol=0.01)  # kept moving from where it was
    assert (env.phase - phases).abs().max() > 1.0  # but its phases were redrawn


def test_fallen_robot_terminates_with_penalty():
    env = quiet_standing(2)
    flipped = torch.tensor([[0.0, 1.0, 0.0, 0.0]])  # upside down
    env.sim.reset(torch.tensor([1]), torch.tensor([[0.0, 0.0, 0.12]]), flipped, torch.zeros(1, 3),
                  torch.zeros(1, 3), env.default_joint_pos[None], torch.zeros(1, 12))
    for _ in range(30):
        _, reward, dones, _ = env.step(torch.zeros(2, 12))
        if dones[1]:
            break
    assert dones[1] and env.terminated[1] and not env.terminated[0]
    assert reward[1] == pytest.approx(-env.cfg.rewards.termination_penalty)
    assert env.state.base_pos[1, 2] > 0.3  # reset to the start height


def test_diverged_env_is_reset_and_training_goes_on():
    env = quiet_standing(3)
    env.step(torch.zeros(3, 12))
    env.sim._qvel[2, :] = 1e12
    _, _, dones, _ = env.step(torch.zeros(3, 12))
    assert dones.tolist() == [False, False, True]
    _, reward, _, _ = env.step(torch.zeros(3, 12))
    assert torch.isfinite(reward).all()


def test_same_seed_same_rollout():
    def rollout():
        env = osc_env(8)
        gen = torch.Generator().manual_seed(0)
        for _ in range(30):
            obs, reward, _, _ = env.step(torch.randn(8, 12, generator=gen))
        return obs["actor"], reward

    (a_obs, a_rew), (b_obs, b_rew) = rollout(), rollout()
    assert torch.equal(a_obs, b_obs) and torch.equal(a_rew, b_rew)


# --- oscillators in the env ----------------------------------------------------------------------------


def test_standing_robot_oscillators_settle_mid_stance():
    env = quiet_standing(8)
    env.phase[:] = torch.linspace(0.1, 6.2, 32).reshape(8, 4)
    for _ in range(400):  # 4 s with a zero policy and a standing command
        env.step(torch.zeros(8, 12))
    # Each phase rests at the stable fixed point of eq. 5 for its foot's load, cos(phi) = 1/(4 GRF) - 1:
    # 3*pi/2 at a quarter of the weight. This robot rests nose-up, hind feet carrying more than the
    # front ones, so the front phases sit later in stance and the hind ones earlier.
    expected = TWO_PI - torch.arccos(1.0 / (4.0 * env.grf) - 1.0)
    assert torch.allclose(env.phase, expected, atol=0.05)
    distance = torch.remainder(env.phase - 1.5 * math.pi + math.pi, TWO_PI) - math.pi
    assert distance.abs().max() < math.pi / 4  # well inside stance [pi, 2*pi)
    assert env.get_observations()["critic"][:, -16:-12].abs().max() < 1.0  # phase velocities near 0


def test_per_substep_force_differs_from_held_force():
    envs = [quiet_standing(4, hold_grf=hold) for hold in (False, True)]
    for env in envs:
        env.phase[:] = torch.tensor([0.3, 1.7, 3.1, 4.5])
    for _ in range(40):  # the robot lands and loads its feet: forces change within control steps
        for env in envs:
            env.step(torch.zeros(4, 12))
    assert torch.equal(envs[0].state.base_pos, envs[1].state.base_pos)  # the physics is the same
    assert (envs[0].phase - envs[1].phase).abs().max() > 1e-3


def test_grf_is_normalised_by_the_models_weight():
    env = quiet_standing(2)
    for _ in range(200):
        env.step(torch.zeros(2, 12))
    assert env.grf.sum(dim=1).tolist() == pytest.approx([1.0, 1.0], abs=0.05)
    assert env.grf_normaliser == pytest.approx(8.952 * 9.81, rel=1e-3)


def test_a_reward_stage_takes_new_entries_by_override_and_refuses_names_that_are_no_reward():
    # The envelope recipe's stage already replaces two weights; a third one (E52) is added on the command line.
    staged = apply_overrides(MiniCheetahOscCfg(), ["rewards.second_stage.weights={swing_grf: 10.0, stance_grf: 10.0}"])
    for extra in ("rewards.second_stage.weights.swing_contact=5.0", "rewards.second_stage.weights={swing_contact: 5.0}"):
        cfg = apply_overrides(staged, [extra])
        cfg.validate()
        assert cfg.rewards.second_stage.weights == {"swing_grf": 10.0, "stance_grf": 10.0, "swing_contact": 5.0}
    with pytest.raises(ConfigError, match="'rewards.second_stage.weights.swing_contct' names no entry of rewards.weights"):
        apply_overrides(staged, ["rewards.second_stage.weights.swing_contct=5.0"]).validate()
    with pytest.raises(ConfigError, match="did you mean 'rewards.weights.swing_contact'"):
        apply_overrides(staged, ["rewards.weights.swing_contct=5.0"])  # rewards.weights itself stays closed


def test_each_step_keeps_its_weighted_reward_terms_and_they_add_up_to_the_reward():
    env = osc_env(3)
    for _ in range(5):
        env.step(torch.zeros(3, env.num_actions))
    assert list(env.reward_terms) == list(env.reward_weights)
    total = torch.stack(list(env.reward_terms.values())).sum(dim=0)
    penalty = env.cfg.rewards.termination_penalty * env.terminated.float()
    assert torch.allclose(total - penalty, env.rew_buf, atol=1e-6)
    assert env.reward_terms["tracking_lin_vel"].gt(0).all()  # a positive term, weighted and scaled by dt
