"""Analysis modules on synthetic data with known answers, plus one small end-to-end rollout.

The gait metrics themselves (touchdowns, RPD, classification) are tested in test_gait_metrics.py.
"""

import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from analysis import balanced_legs, disturbance, gait, gait_emergence, pace_to_trot, report
from analysis.rollout import (
    EvalSettings,
    Job,
    PolicyRun,
    StackedPolicy,
    eval_env_cfg,
    limit_per_config,
    rollout,
    run_jobs,
)
from gym_envs import env_cfg_class, make_env
from gym_envs.config import apply_overrides

PI = math.pi
DT = 0.01  # control step [s] of the synthetic records


# --- disturbance scoring (Table I) ----------------------------------------------------------------


def test_fall_in_window_fails_and_recovered_push_does_not():
    ball = disturbance.PROTOCOL_BALL
    tl = ball.timeline(0.01)
    flags = np.zeros((4, tl["total"] - 1), bool)  # recorded from the commanded step on
    first_push_sample = tl["first_push"] - 1
    flags[0, first_push_sample + 30] = True  # falls 0.3 s after its push
    # robot 1 is pushed and recovers: no termination at all
    flags[2, 200] = True  # falls while settling, before any push: still a failure
    flags[3, tl["fail_window_end"]] = True  # falls on the very last test step: after the sample that decides
    fails = disturbance.failed(flags, tl["fail_window_end"])
    assert fails.tolist() == [True, False, True, False]
    assert disturbance.failure_rate(fails) == pytest.approx(50.0)
    assert disturbance.failed(flags, tl["pre_push_end"]).tolist() == [False, False, True, False]


def test_push_ball_timeline_and_layout_match_the_protocol():
    ball = disturbance.PROTOCOL_BALL
    tl = ball.timeline(0.01)
    assert ball.robots == 1800
    assert tl["total"] == 1 + 500 + 1000
    assert tl["first_push"] == 1 + 500 + 100 and tl["last_push"] == 1 + 500 + 149
    assert tl["fail_window_end"] == 500 + 998 + 1  # recorded samples: settling + test samples 0..998
    step, delta = ball.pushes(2.5, 0.01)
    n = np.array([0, 35, 36, 1799])
    assert step[n].tolist() == [601, 601, 602, 650]
    theta = ball.angles()
    assert theta[0] == 0.0 and theta[-1] == pytest.approx(2 * PI)  # the release's 0 and 360 degrees
    np.testing.assert_allclose(np.linalg.norm(delta, axis=1), 2.5)
    np.testing.assert_allclose(delta[36], [2.5, 0.0], atol=1e-12)  # slot 1, direction 0 is +x
    even = disturbance.PushBall(direction_mode="even").angles()
    assert np.diff(even) == pytest.approx(np.full(35, PI / 18))


def test_fewer_push_slots_keep_the_directions_and_the_half_second_span():
    ball = disturbance.default_ball(quick=False, slots=10)
    assert ball.robots == 360 and ball.directions == disturbance.PROTOCOL_BALL.directions
    small, full = ball.timeline(0.01), disturbance.PROTOCOL_BALL.timeline(0.01)
    # 10 slots 0.05 s apart cover the protocol's 0.5 s (50 slots 0.01 s apart): a whole gait cycle either way
    assert ball.slot_interval_steps(0.01) == 5 and disturbance.PROTOCOL_BALL.slot_interval_steps(0.01) == 1
    assert small["last_push"] == full["first_push"] + 45 and full["last_push"] == full["first_push"] + 49
    assert {k: v for k, v in small.items() if k != "last_push"} == {k: v for k, v in full.items() if k != "last_push"}
    step, _ = ball.pushes(2.0, 0.01)
    assert sorted(set(step.tolist())) == list(range(full["first_push"], full["first_push"] + 46, 5))
    assert disturbance.default_ball(quick=True) is disturbance.QUICK_BALL
    with pytest.raises(ValueError, match="do not fit"):
        disturbance.default_ball(quick=False, slots=2000).timeline(0.01)


def _osc_policy(profile):
    from gym_envs.registry import env_cfg_class, train_cfg_class
    from learning.runner_config import apply_split_overrides, profile_overrides

    env_cfg, _ = apply_split_overrides(env_cfg_class("mini_cheetah_osc")(), train_cfg_class("mini_cheetah_osc")(),
                                       profile_overrides(profile, "mini_cheetah_osc"))
    return SimpleNamespace(env_cfg=env_cfg)


def test_push_command_stays_inside_every_policys_trained_commands():
    paper, recipe = _osc_policy(None), _osc_policy("cpu_oscillators")
    assert disturbance.trained_forward_speed(paper.env_cfg) == 3.0  # v_x in {-3, -1, 0, 1, 3}
    assert disturbance.trained_forward_speed(recipe.env_cfg) == 2.0  # v_x in {1, 2}
    assert disturbance.push_command([paper]) == 3.0  # the protocol's
    assert disturbance.push_command([paper, recipe]) == 2.0  # not outside the recipe's task
    assert disturbance.push_command([paper, recipe], requested=3.0) == 3.0
    backwards = SimpleNamespace(env_cfg=SimpleNamespace(commands=SimpleNamespace(lin_vel_x_choices=(), lin_vel_x=(-1.0, 0.0))))
    with pytest.raises(ValueError, match="--push_command"):
        disturbance.push_command([backwards])


def test_mean_std_is_population_std():
    mean, std = disturbance.mean_std([0.0, 2.0])
    assert (mean, std) == (1.0, 1.0)


def test_failure_table_bolds_lowest_mean_and_ties():
    rates = {
        "000": {1.5: [0.0, 0.0], 2.0: [5.0, 15.0]},
        "110": {1.5: [0.0, 1 / 18], 2.0: [1.0, 1.0]},
        "111": {1.5: [0.0, 0.0], 2.0: [1.0, 1.0]},
    }
    lines = disturbance.format_failure_table(rates).splitlines()
    assert lines[0] == "| Impulse [m/s] | 000 | 110 | 111 |"
    # exact zeros tie and are bold; 0.03 shows as 0.0 but is not the lowest
    assert lines[2] == "| 1.5 | **0.0 ± 0.0** | 0.0 ± 0.0 | **0.0 ± 0.0** |"
    assert lines[3] == "| 2.0 | 10.0 ± 5.0 | **1.0 ± 0.0** | **1.0 ± 0.0** |"
    missing = disturbance.format_failure_table({"000": {1.5: [1.0]}, "111": {}}, magnitudes=[1.5])
    assert missing.splitlines()[2] == "| 1.5 | **1.0 ± 0.0** | – |"


# --- report formatting ----------------------------------------------------------------------------


def test_markdown_table_escapes_pipes_and_checks_widths():
    text = report.markdown_table(["a", "b|c"], [[1, "x|y"]])
    assert text.splitlines() == ["| a | b\\|c |", "|---|---|", "| 1 | x\\|y |"]
    with pytest.raises(ValueError, match="2 columns"):
        report.markdown_table(["a", "b"], [[1]])


def test_paper_table_keeps_the_papers_numbers_and_bold():
    lines = report.paper_table_markdown().splitlines()
    assert lines[0] == "| Impulse [m/s] | 000 | 100 | 101 | 010 | 110 | 011 | 111 |"
    assert lines[3] == ("| 2.0 | 1.7 ± 2.5 | 4.1 ± 5.2 | 0.9 ± 1.2 | **0.0 ± 0.0** | 0.0 ± 0.1 | **0.0 ± 0.0** "
                        "| 0.0 ± 0.1 |")
    assert lines[-1].endswith("| **7.4 ± 4.0** |")


def test_table_claims_hold_only_where_a_permutation_test_over_policies_says_so():
    def rates(policies, spread=0.1):
        return {c: {3.0: [m + spread * k for k in range(policies)], 3.5: [m + 5 + spread * k for k in range(policies)]}
                for c, m in {"100": 20.0, "101": 18.0, "010": 4.0, "011": 3.0, "111": 2.0}.items()}
    claims = report.table_claims(rates(4))
    assert any(c.startswith("ORC(111) lowest at 3 m/s (paper: yes): yes (p = 0.014; 4 vs 4 policies)") for c in claims)
    assert any("at 3.5 m/s (paper: yes): yes (p < 0.001; 8 vs 8 policies); 8.7 % vs 24.1 %" in c for c in claims)
    # One policy per configuration: the means still go the paper's way, but nothing is shown.
    claims = report.table_claims(rates(1))
    assert any(c.startswith("ORC(111) lowest at 3 m/s (paper: yes): not shown (p = 0.500; 1 vs 1 policies)")
               for c in claims)
    flipped = rates(4)
    flipped["111"][3.0] = [30.0, 31.0, 32.0, 33.0]
    assert any(c.startswith("ORC(111) lowest at 3 m/s (paper: yes): no") for c in report.table_claims(flipped))


# --- balanced legs --------------------------------------------------------------------------------


def test_balanced_leg_statistic_on_synthetic_grf():
    t = np.arange(1000)
    stance = ((t // 20) % 2 == 0).astype(float)  # half the time on the ground
    trot = np.stack([stance, 1 - stance, 1 - stance, stance], axis=1) * 0.5  # diagonal pairs share the weight
    three_legged = np.stack([np.zeros(1000), np.full(1000, 1 / 3), np.full(1000, 1 / 3), np.full(1000, 1 / 3)], 1)
    g = balanced_legs.mean_grf_per_leg(np.stack([trot, three_legged]))
    np.testing.assert_allclose(g[0], 0.25)
    np.testing.assert_allclose(g[1], [0.0, 1 / 3, 1 / 3, 1 / 3])
    stats = balanced_legs.leg_statistics(g)
    assert stats["frac_leg_near_zero"] == 0.5
    assert stats["mean_max_deviation"] == pytest.approx(0.125)
    with pytest.raises(ValueError, match="N, T, 4"):
        balanced_legs.mean_grf_per_leg(trot)


def test_leg_use_figure_marks_each_legs_mean_over_policies_with_its_interval():
    import matplotlib.pyplot as plt
    from analysis.stats import policy_interval

    rng = np.random.default_rng(0)
    # Two policies that load RF differently: the interval over policies must span both of their means.
    policies = [np.clip(0.25 + 0.02 * rng.standard_normal((50, 4)) + [[shift, 0, 0, 0]], 0, 1) for shift in (-0.1, 0.1)]
    intervals = [policy_interval(policies, lambda g, j=j: g[:, j].mean()) for j in range(4)]
    low, high = intervals[0][1:]
    assert low < policies[0][:, 0].mean() + 0.02 and high > policies[1][:, 0].mean() - 0.02
    assert intervals[1][2] - intervals[1][1] < 0.05  # the legs the policies agree on: narrow
    fig = balanced_legs.plot({"111": np.concatenate(policies)}, {"111": intervals}, {"111": 2})
    bars = fig.axes[0].containers
    assert [b.lines[0].get_ydata()[0] for b in bars] == pytest.approx([i[0] for i in intervals])
    assert "mean over 2 policies" in fig.axes[0].get_title()
    plt.close(fig)


# --- gait emergence and pace to trot --------------------------------------------------------------


def _gait_grf(rpd, period=40, steps=400, duty=0.5):
    """Square-wave GRF (T, 4): RF touches down every `period` steps, leg j lags it by rpd_j."""
    t = np.arange(steps)
    lags = np.concatenate([[0.0], rpd]) / (2 * PI) * period
    phase = np.mod(t[:, None] - lags[None], period) / period
    return np.where(phase < duty, 0.5, 0.0)


def test_first_cycles_rpd_recovers_the_starting_gait():
    grf = np.stack([_gait_grf([PI, 0.0, PI]), _gait_grf([PI, PI, 0.0]), np.zeros((400, 4))])
    rpd = gait_emergence.first_cycles_rpd(grf, DT)
    np.testing.assert_allclose(rpd[0], [PI, 0.0, PI], atol=1e-9)
    np.testing.assert_allclose(rpd[1], [PI, PI, 0.0], atol=1e-9)
    assert np.isnan(rpd[2]).all()  # never touched down


def test_settling_time_is_first_checkpoint_with_90_percent_final_labels():
    times = [5.0, 10.0, 15.0, 20.0]
    labels = np.array([["pace", "trot", "trot", "trot"]] * 9 + [["trot", "pace", "pace", "trot"]])
    assert gait_emergence.settling_time(times, labels) == 10.0  # 9 of 10 already trot at 10 s
    labels[9] = ["pace", "pace", "pace", "trot"]
    assert gait_emergence.settling_time(times, labels) == 10.0
    labels[:2, 1] = "pace"
    assert gait_emergence.settling_time(times, labels) == 15.0


def test_ideal_gait_images_cover_the_cube_corners_for_pronk():
    images = gait_emergence.ideal_gait_images()
    assert len(images["pronk"]) == 8 and len(images["trot"]) == 2 and len(images["pace"]) == 2


def test_pace_to_trot_selection_prefers_a_real_pace_to_trot_run():
    steps = 1000
    pace, trot = _gait_grf([PI, 0.0, PI], steps=steps), _gait_grf([PI, PI, 0.0], steps=steps)
    switching = np.concatenate([pace[:300], trot[300:]])  # pace first, trot long before 10 s
    choice = pace_to_trot.select_run(np.stack([trot, switching, pace]), DT)
    assert choice["index"] == 1 and choice["candidates"] == 1
    assert (choice["start_label"], choice["end_label"]) == ("pace", "trot")
    fallback = pace_to_trot.select_run(np.stack([trot, pace]), DT)
    assert fallback["rule"].startswith("fallback") and fallback["candidates"] == 0


def test_crossings_and_stance_share():
    phase = np.mod(np.linspace(0, 4 * PI, 100, endpoint=False), 2 * PI)[:, None]  # two turns
    zero, pi = pace_to_trot.crossings(phase[:, 0])
    assert zero.size == 1 and pi.size == 2
    grf = (phase >= PI) * 0.4  # force only in stance
    assert gait.stance_share(phase, grf)[0] == pytest.approx(1.0)


# --- rollout helper -------------------------------------------------------------------------------


def _tiny_run(orc="111", seed=0) -> PolicyRun:
    """A random-weight rsl-rl actor (MLPModel with a Gaussian head, as learning trains) for ORC `orc`."""
    from rsl_rl.models import MLPModel

    cfg = env_cfg_class("mini_cheetah_osc")()
    cfg.osc.orc = orc
    cfg.env.num_envs = 1
    cfg.sim.num_threads = 1
    env = make_env("mini_cheetah_osc", cfg)  # applies the ORC to cfg's observation lists
    torch.manual_seed(seed)
    actor = MLPModel(env.get_observations(), {"actor": ["actor"]}, "actor", env.num_actions, hidden_dims=(16, 16),
                     distribution_cfg={"class_name": "GaussianDistribution", "init_std": 1.0})
    actor.eval()
    return PolicyRun(f"random_{orc}_{seed}", env.cfg, actor)


def test_eval_overrides_set_the_evaluation_setting():
    run = _tiny_run("110")
    cfg = eval_env_cfg(run.env_cfg, EvalSettings(coupling=1.0), num_envs=3, seed=7)
    assert cfg.osc.orc == "111" and cfg.osc.coupling_max == 1.0  # coupling switched on for a C=0 policy
    assert run.env_cfg.osc.orc == "110"  # the run's own config is untouched
    assert not cfg.push.enabled and not cfg.domain_rand.randomize_friction and cfg.init_state.mode == "default"
    assert cfg.osc.process_noise_std == 0.0 and cfg.osc.omega_noise_std == 0.0 and cfg.osc.coupling_noise_std == 0.0
    assert cfg.observations.noise_scale == 0.0 and cfg.commands.lin_vel_x_choices == ()
    assert (cfg.env.num_envs, cfg.env.seed) == (3, 7)
    off = eval_env_cfg(_tiny_run("111").env_cfg, EvalSettings(coupling=0.0, process_noise_std=0.25), 2)
    assert off.osc.orc == "111" and off.osc.coupling_max == 0.0 and off.osc.process_noise_std == 0.25


def test_a_checkpoint_past_its_second_reward_stage_is_paid_that_stage_in_evaluation():
    run = _tiny_run("111")
    staged = apply_overrides(run.env_cfg, ["rewards.second_stage.start_step=100",
                                           "rewards.second_stage.weights={tracking_lin_vel: 8.0}"])
    paid = {}
    for trained_steps in (100, 101):  # at the stage's start, then past it
        cfg = eval_env_cfg(staged, EvalSettings(), num_envs=2, num_threads=1, trained_steps=trained_steps)
        r = rollout(run.policy, cfg, 20, record=("reward_terms",), progress=False)
        paid[trained_steps] = r.data["reward_terms"][..., r.info["reward_terms"].index("tracking_lin_vel")]
    assert paid[100].min() > 0  # the rewards change, the robots do not: same trajectory, twice the weight
    np.testing.assert_allclose(paid[101], 2.0 * paid[100], rtol=1e-5)


def test_stacked_policy_routes_rows_to_their_policy():
    obs = TensorDict({"actor": torch.arange(5.0)[:, None].expand(5, 3)}, batch_size=[5])
    stacked = StackedPolicy([lambda o: o["actor"][:, :1] * 0, lambda o: o["actor"][:, :1] + 100], [2, 3])
    assert stacked(obs)[:, 0].tolist() == [0.0, 0.0, 102.0, 103.0, 104.0]


def test_rollout_end_to_end_with_a_random_policy():
    run = _tiny_run("111")
    cfg = eval_env_cfg(run.env_cfg, EvalSettings(), num_envs=4, num_threads=1)
    push_step = np.array([-1, 10, -1, -1])
    push_delta = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    r = rollout(run.policy, cfg, 50, command=(1.0, 0.0, 0.0),
                record=("grf", "phase", "base_lin_vel", "base_height", "command", "terminated"),
                push_step=push_step, push_delta=push_delta, progress=False)
    assert r.data["grf"].shape == (4, 50, 4) and r.data["grf"].dtype == np.float32
    assert r.data["base_height"].shape == (4, 50) and r.data["terminated"].dtype == np.bool_
    assert ((r.data["grf"] >= 0) & (r.data["grf"] <= 1)).all()
    assert ((r.data["phase"] >= 0) & (r.data["phase"] < 2 * PI)).all()
    assert r.initial_phase.shape == (4, 4) and r.times[0] == pytest.approx(0.01)
    fell = r.fell()
    np.testing.assert_allclose(r.data["command"][~fell], np.broadcast_to([1.0, 0.0, 0.0], (int((~fell).sum()), 50, 3)))
    if not fell[1]:  # the pushed robot is 2 m/s faster right after the push than the others
        assert r.data["base_lin_vel"][1, 10, 0] > r.data["base_lin_vel"][[0, 2, 3], 10, 0].max() + 1.0


def test_run_jobs_shares_a_batch_and_splits_results_per_policy(capsys):
    runs = [_tiny_run("111", 0), _tiny_run("111", 1), _tiny_run("100", 2)]
    out = run_jobs([Job(runs[0], 2), Job(runs[1], 3), Job(runs[2], 2)], 5, record=("grf", "terminated"),
                   num_threads=1, label="demo")
    assert [o.num_envs for o in out] == [2, 3, 2]
    assert [o.info["run"] for o in out] == [r.name for r in runs]
    assert out[0].info["seed"] == out[1].info["seed"] != out[2].info["seed"]  # 111s batched, 100 apart
    assert limit_per_config(runs, 1) == [runs[0], runs[2]]
    # Not on a terminal: no bar, one summary line for the whole call.
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("demo: 3 jobs, 7 robots x 5 steps in 2 batches"), err


def test_report_with_an_empty_runs_folder_is_a_one_line_error(tmp_path, capsys):
    assert report.main(["--runs", str(tmp_path), "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("analysis.report: error: no runs in") and "\n" not in err
    assert not (tmp_path / "out").exists()


def test_locomotion_check_of_a_standing_policy():
    from analysis.locomotion import check_locomotion

    run = _tiny_run("111")

    def stand(obs):
        return torch.zeros(obs.batch_size[0], 12)

    check = check_locomotion(stand, run.env_cfg, command=1.0, warmup_s=0.5, measure_s=5.0, num_envs=3,
                             num_threads=1)
    assert check.falls == 0 and abs(check.mean_velocity) < 0.1
    assert check.tracking_error == pytest.approx(1.0, abs=0.1)  # it stands while asked to walk at 1 m/s
    assert check.gaits == {"transition": 1.0} and check.regular_share == 0.0  # no footfalls, no gait


def test_one_sample_is_decided_from_the_policys_inputs():
    blind, seeing = _tiny_run("011"), _tiny_run("111")
    assert make_env("mini_cheetah_osc", eval_env_cfg(blind.env_cfg, EvalSettings(), 2)).robots_indistinguishable()
    assert not make_env("mini_cheetah_osc", eval_env_cfg(seeing.env_cfg, EvalSettings(), 2)).robots_indistinguishable()
    noisy = eval_env_cfg(blind.env_cfg, EvalSettings(observation_noise=True), 2)
    assert not make_env("mini_cheetah_osc", noisy).robots_indistinguishable()
    assert not make_env("mini_cheetah_osc", blind.env_cfg).robots_indistinguishable()  # training: randomised

    # Two phase-blind policies in one batch, some robots pushed: robots are one sample with those that
    # share their policy, command and push; the oscillator phases stay each robot's own.
    other = _tiny_run("011", 1)
    push_step = np.array([-1, -1, 5, 5, -1, -1, -1])
    push_delta = np.array([[0.0, 0.0]] * 2 + [[1.0, 0.0], [-1.0, 0.0]] + [[0.0, 0.0]] * 3)
    out = run_jobs([Job(blind, 4, push_step[:4], push_delta[:4]), Job(other, 3, push_step[4:], push_delta[4:])], 20,
                   record=("grf", "phase", "base_lin_vel", "terminated"), num_threads=1, progress=False)
    assert out[0].sample.tolist() == [0, 0, 2, 3] and out[1].sample.tolist() == [4, 4, 4]
    assert not out[0].robots_alike() and out[0].rows([0, 1]).robots_alike() and out[1].robots_alike()
    assert np.array_equal(out[1].data["base_lin_vel"][1], out[1].data["base_lin_vel"][0])
    assert not np.array_equal(out[0].data["base_lin_vel"][2], out[0].data["base_lin_vel"][3])
    assert not np.array_equal(out[1].data["phase"][1], out[1].data["phase"][0])
    seen = run_jobs([Job(seeing, 3)], 5, record=("grf", "terminated"), num_threads=1, progress=False)[0]
    assert seen.sample.tolist() == [0, 1, 2] and not seen.robots_alike()


def test_envelope_scores_tracking_per_axis_falls_and_standing():
    from analysis import envelope
    from analysis.rollout import Rollout

    t, n = 500, 2
    lin, ang = np.zeros((n, t, 3)), np.zeros((n, t, 3))
    lin[0, :, 0], lin[1, :, 0] = 1.0, 0.6  # robot 1 is 0.4 m/s slow
    ang[:, :, 2] = 0.9
    data = {"grf": np.zeros((n, t, 4)), "base_lin_vel": lin, "base_ang_vel": ang, "terminated": np.zeros((n, t), bool)}
    r = envelope.command_result(Rollout(data, np.zeros((n, 4)), 0.01, t), "walk and turn", (1.0, 0.0, 1.0))
    assert r.tracked == pytest.approx((0.8, 0.0, 0.9)) and r.error == pytest.approx((0.2, 0.0, 0.1))
    assert r.met and r.gaits == {envelope.NO_STEPS: 1.0} and r.step_frequency == 0.0  # no footfalls: it stood
    data["grf"][:, 50::100, :] = 0.5  # one touchdown per second per foot (10 ms loads, 0.99 s unloaded)
    stepping = envelope.command_result(Rollout(data, np.zeros((n, 4)), 0.01, t), "x", (1.0, 0.0, 1.0))
    assert stepping.step_frequency == 1.0 and stepping.gaits == {"pronk": 1.0}  # all four feet land together
    data["grf"][:, :, 1] = 1.0  # LF holds the ground: the others step, the window has no LF touchdown
    assert envelope.command_result(Rollout(data, np.zeros((n, 4)), 0.01, t), "x", (1.0, 0.0, 1.0)).gaits == {
        envelope.IRREGULAR: 1.0}
    data["grf"][:, :, 1] = 0.0
    data["grf"][:, 50::100, 1] = 0.5
    data["terminated"][1, 100] = True
    assert not envelope.command_result(Rollout(data, np.zeros((n, 4)), 0.01, t), "x", (1.0, 0.0, 1.0)).met
    lin[1, :, 0] = 0.0  # robot 1 does not walk: mean error 0.5 > 0.25
    data["terminated"][:] = False
    missed = envelope.command_result(Rollout(data, np.zeros((n, 4)), 0.01, t), "x", (1.0, 0.0, 1.0))
    assert not missed.met
    section = "\n".join(report._section_envelope({"sizes": envelope.PROTOCOL, "results": [r, missed]}))
    assert "| walk and turn | +0.80 / +0.00 / +0.90 | 0.20 | yes |" in section and "| x | +0.50" in section
    assert section.rstrip().endswith("| 1.0 |")


def test_jobs_can_carry_their_own_command():
    run = _tiny_run("111")
    out = run_jobs([Job(run, 2, command=(0.0, 0.0, 1.5)), Job(run, 2)], 3, command=(1.0, 0.0, 0.0),
                   record=("command", "terminated"), num_threads=1, progress=False)
    assert out[0].data["command"][:, -1].tolist() == [[0.0, 0.0, 1.5]] * 2
    assert out[1].data["command"][:, -1].tolist() == [[1.0, 0.0, 0.0]] * 2
