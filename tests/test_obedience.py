"""Oscillator obedience (analysis.obedience): the measures on synthetic records, then a shipped policy."""

import math

import numpy as np
import pytest

from analysis import obedience
from analysis.gait import IDEAL_GAITS, TRANSITION
from analysis.rollout import Rollout, load_policy_run
from learning.runs import shipped_policy_dir

PI = math.pi
DT = 0.01


def synthetic_rollout(rpd, robots=3, seconds=10.0, freq=2.5, speed=1.0, follow=True):
    """Robots whose oscillators run in the gait `rpd` ((3,), or (robots, 3) for one pattern each); feet
    loaded in their stance half when follow=True, else every foot loaded in RF's stance half (a pronk that
    ignores the other oscillators)."""
    t = (np.arange(int(seconds / DT)) + 1) * DT
    rf = 2 * PI * freq * t[:, None] + np.linspace(0.3, 2.0, robots)[:, None, None]
    rpd = np.broadcast_to(rpd, (robots, 3))
    phase = np.mod(rf - np.concatenate([np.zeros((robots, 1)), rpd], axis=1)[:, None, :], 2 * PI)  # (N, T, 4)
    stance = phase >= PI if follow else np.repeat(phase[..., :1] >= PI, 4, axis=-1)
    grf = 0.5 * stance
    vel = np.zeros(phase.shape[:2] + (3,))
    vel[..., 0] = speed
    data = {"grf": grf, "phase": phase, "base_lin_vel": vel, "terminated": np.zeros(phase.shape[:2], bool)}
    return Rollout(data, phase[:, 0], DT, phase.shape[1])


@pytest.mark.parametrize("gait", obedience.STARTED_GAITS)
def test_a_follower_obeys_every_gait(gait):
    res = obedience.started_gait_result(synthetic_rollout(IDEAL_GAITS[gait]), gait)
    assert res.obeyed == 1.0 and res.phase_agreement == 1.0
    assert res.stance_share == pytest.approx(1.0)
    assert res.velocity == pytest.approx(1.0)
    assert res.falls == 0 and not res.identical


def test_a_pronker_obeys_only_pronk():
    for gait in ("trot", "pace", "bound"):
        res = obedience.started_gait_result(synthetic_rollout(IDEAL_GAITS[gait], follow=False), gait)
        assert res.obeyed == 0.0 and res.contact_mix["pronk"] == 1.0
        assert res.phase_agreement == 0.0  # its oscillators say `gait`, its feet say pronk
        assert res.stance_share == pytest.approx(0.5, abs=0.02)  # half its load lands in swing


def test_stepping_in_place_earns_the_label_but_does_not_walk():
    for speed, walking in ((0.05, 0.0), (0.6, 1.0)):
        started = {g: obedience.started_gait_result(synthetic_rollout(IDEAL_GAITS[g], speed=speed), g)
                   for g in obedience.STARTED_GAITS}
        assert all(s.obeyed == 1.0 and s.walking == walking for s in started.values())
        assert obedience.Obedience("p", "111", started).obeys() == bool(walking)


def test_walking_is_judged_against_the_command_asked_for():
    rollout = synthetic_rollout(IDEAL_GAITS["bound"], speed=0.6)
    assert obedience.started_gait_result(rollout, "bound", command=1.0).walking == 1.0
    assert obedience.started_gait_result(rollout, "bound", command=2.0).walking == 0.0  # 0.6 m/s under 2 m/s


def test_robots_alike_is_decided_by_their_samples_not_their_records():
    r = synthetic_rollout(IDEAL_GAITS["trot"])
    assert not obedience.started_gait_result(r, "trot").identical
    r.data["grf"][:] = r.data["grf"][:1]  # equal records alone do not make one sample
    assert not obedience.started_gait_result(r, "trot").identical
    r.sample = np.zeros(r.num_envs, dtype=int)
    assert obedience.started_gait_result(r, "trot").identical


def test_free_phases_tell_a_follower_from_a_pronker():
    """sigma = 0 from random phases: a follower's feet keep each robot's own RPD, a pronker's do not."""
    patterns = np.random.default_rng(0).uniform(0.0, 2 * PI, size=(6, 3))
    follower = obedience.free_phase_result(synthetic_rollout(patterns, robots=6))
    assert follower.rpd_distance < 0.1 and follower.label_agreement == 1.0 and follower.invalid == 0.0
    pronker = obedience.free_phase_result(synthetic_rollout(patterns, robots=6, follow=False))
    assert pronker.rpd_distance > 1.0 and pronker.invalid == 0.0


def test_free_phases_count_a_leg_that_never_lands_as_not_following():
    rollout = synthetic_rollout(IDEAL_GAITS["trot"], robots=4)
    rollout.data["grf"][0, :, 3] = 0.0  # one robot holds LH up
    res = obedience.free_phase_result(rollout)
    assert res.invalid == 0.25 and res.rpd_distance < 0.1  # the median of three followers and one inf
    rollout.data["grf"][1:3, :, 3] = 0.0
    res = obedience.free_phase_result(rollout)
    assert res.invalid == 0.75 and np.isinf(res.rpd_distance)


def test_a_leg_carrying_almost_nothing_is_counted():
    rollout = synthetic_rollout(IDEAL_GAITS["trot"], robots=4)
    assert obedience.coupled_settling_result(rollout).light_leg == 0.0
    rollout.data["grf"][1, :, 2] *= 0.1  # RH carries 0.1 / 3.1 of robot 1's load
    assert obedience.coupled_settling_result(rollout).light_leg == 0.25


def test_settle_times():
    times = [1.0, 2.0, 3.0, 4.0]
    labels = np.array([
        ["trot", "trot", "trot", "trot"],  # settled from the start
        [TRANSITION, "pace", "trot", "trot"],  # from 3 s
        ["trot", TRANSITION, "trot", TRANSITION],  # ends in a transition: never
        ["pronk", "trot", "pronk", "pronk"],  # from 3 s
    ])
    assert obedience.settle_times(times, labels).tolist() == [1.0, 3.0, np.inf, 3.0]


@pytest.fixture(scope="module")
def shipped_3_and_16():
    """Obedience of a phase-blind and a phase-observing shipped policy, with 3 and with 16 robots each.

    3 robots is the size at which rows of a batch are partly handled by vector and partly by scalar
    loops, whose last-bit differences contact dynamics grow (issue 21, measured on AMD EPYC)."""
    runs = [load_policy_run(shipped_policy_dir(orc)) for orc in ("110", "000")]
    return {robots: {r.orc: r for r in obedience.measure(runs, robots=robots, duration_s=10.0, settle_robots=robots,
                                                          settle_duration_s=5.0, progress=False, num_threads=1)}
            for robots in (3, 16)}


def test_shipped_policies_tiny_rollout(shipped_3_and_16):
    by_orc = shipped_3_and_16[3]
    for r in by_orc.values():
        assert set(r.started) == set(obedience.STARTED_GAITS)
        for s in r.started.values():
            assert s.robots == 3
            # sigma = 0 and no process noise: the oscillators keep the started gait, so the oscillator
            # label is the started gait and agreement with the feet is exactly the obeyed share.
            assert s.phase_agreement == pytest.approx(s.obeyed)
            assert 0.0 <= s.stance_share <= 1.0
        assert r.settling.times[-1] == 5.0 and len(r.settling.mix) == 5
    # ORC-000 observes no phases: under deterministic evaluation its robots are one sample repeated.
    assert all(s.identical for s in by_orc["000"].started.values()) and by_orc["000"].settling.identical
    assert not any(s.identical for s in by_orc["110"].started.values()) and not by_orc["110"].settling.identical


def test_what_obedience_reports_does_not_depend_on_the_batch_size(shipped_3_and_16):
    small, large = shipped_3_and_16[3], shipped_3_and_16[16]
    blind_small, blind_large = small["000"], large["000"]
    for g in obedience.STARTED_GAITS:
        a, b = blind_small.started[g], blind_large.started[g]
        assert (a.identical, a.obeyed, a.contact_mix, a.falls > 0) == (b.identical, b.obeyed, b.contact_mix, b.falls > 0)
        assert a.obeyed in (0.0, 1.0)  # one sample: all robots or none
    assert blind_small.settling.mix == blind_large.settling.mix
    assert blind_small.settling.identical and blind_large.settling.identical
    # ORC-110 sees its phases, so its robots are a sample of the started phases; it obeys every gait at
    # either size (100 % of 64 robots per gait in the shipped manifest), so the labels agree too.
    for g in obedience.STARTED_GAITS:
        a, b = small["110"].started[g], large["110"].started[g]
        assert not a.identical and not b.identical
        assert a.obeyed == b.obeyed == 1.0


def test_the_report_shows_free_phases_and_light_legs():
    from analysis import report

    started = {g: obedience.started_gait_result(synthetic_rollout(IDEAL_GAITS[g]), g) for g in obedience.STARTED_GAITS}
    settling = synthetic_rollout(IDEAL_GAITS["trot"], robots=4, seconds=12.0)
    settling.data["grf"][1, :, 2] *= 0.1
    patterns = np.random.default_rng(1).uniform(0.0, 2 * PI, size=(4, 3))
    free = synthetic_rollout(patterns, robots=4, follow=False)
    result = obedience.Obedience("ORC_111/seed0", "111", started, obedience.coupled_settling_result(settling),
                                 obedience.free_phase_result(free))
    section = "\n".join(report._section_obedience({"sizes": obedience.QUICK, "results": [result]}))
    row = next(line for line in section.splitlines() if line.startswith("| 111 |"))
    assert "| 25 % |" in row  # robot 1's light leg
    assert f"| {result.free.rpd_distance:.2f} rad ({100 * result.free.label_agreement:.0f} %) |" in row
    row = obedience._policy_row(result)  # obedience_policies.csv
    # robot 1's RH never passes the touchdown threshold: 3 of 4 coupled robots regular, under the 80 % goal
    assert row[:4] == ["ORC_111/seed0", "111", 0, "0.7500"] and row[7] == "0.2500" and row[-1] == 0
    assert float(row[8]) == pytest.approx(result.free.rpd_distance, abs=1e-4)
    assert obedience._policy_row(obedience.Obedience("p", "110", started))[3:12] == [""] * 9
