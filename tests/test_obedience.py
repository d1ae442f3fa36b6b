"""Oscillator obedience (analysis.obedience): the measures on synthetic records, then a shipped policy."""

import math

import numpy as np
import pytest

from analysis import obedience
from analysis.gait import IDEAL_GAITS, TRANSITION
from analysis.rollout import Rollout, load_policy_run, SHIPPED_POLICIES

PI = math.pi
DT = 0.01


def synthetic_rollout(rpd, robots=3, seconds=10.0, freq=2.5, speed=1.0, follow=True):
    """Robots whose oscillators run in the gait `rpd`; feet loaded in their stance half when follow=True,
    else every foot loaded in RF's stance half (a pronk that ignores the other oscillators)."""
    t = (np.arange(int(seconds / DT)) + 1) * DT
    rf = 2 * PI * freq * t[:, None] + np.linspace(0.3, 2.0, robots)[:, None, None]
    phase = np.mod(rf - np.concatenate([[0.0], rpd]), 2 * PI)  # (N, T, 4)
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


def test_identical_robots_are_detected():
    r = synthetic_rollout(IDEAL_GAITS["trot"])
    r.data["grf"][:] = r.data["grf"][:1]
    assert obedience.started_gait_result(r, "trot").identical


def test_settle_times():
    times = [1.0, 2.0, 3.0, 4.0]
    labels = np.array([
        ["trot", "trot", "trot", "trot"],  # settled from the start
        [TRANSITION, "pace", "trot", "trot"],  # from 3 s
        ["trot", TRANSITION, "trot", TRANSITION],  # ends in a transition: never
        ["pronk", "trot", "pronk", "pronk"],  # from 3 s
    ])
    assert obedience.settle_times(times, labels).tolist() == [1.0, 3.0, np.inf, 3.0]


def test_shipped_policies_tiny_rollout():
    runs = [load_policy_run(f"{SHIPPED_POLICIES}/ORC_{orc}") for orc in ("110", "000")]
    results = obedience.measure(runs, robots=3, duration_s=10.0, settle_robots=3, settle_duration_s=5.0,
                                progress=False, num_threads=1)
    by_orc = {r.orc: r for r in results}
    for r in results:
        assert set(r.started) == set(obedience.STARTED_GAITS)
        for s in r.started.values():
            assert s.robots == 3
            # sigma = 0 and no process noise: the oscillators keep the started gait, so the oscillator
            # label is the started gait and agreement with the feet is exactly the obeyed share.
            assert s.phase_agreement == pytest.approx(s.obeyed)
            assert 0.0 <= s.stance_share <= 1.0
        assert r.settling.times[-1] == 5.0 and len(r.settling.mix) == 5
    # ORC-000 observes no phases: under deterministic evaluation its robots all move alike.
    assert all(s.identical for s in by_orc["000"].started.values())
    assert not any(s.identical for s in by_orc["110"].started.values())
