"""Tests for analysis.gait on synthetic footfall patterns."""

import math

import numpy as np
import pytest

from analysis.gait import (
    GAIT_LABELS,
    IDEAL_GAITS,
    TRANSITION,
    agreement,
    circular_difference,
    circular_mean,
    classify,
    classify_gait,
    footfall_phases,
    gait_counts,
    oscillator_rpd,
    phase_touchdowns,
    rpd_timeseries,
    touchdowns,
    window_rpd,
)

PI = math.pi
DT = 0.01  # control step [s] of the synthetic records
PERIOD = 40  # steps: 2.5 Hz at DT
T = 4000  # 40 s


def square_wave(rpd, n_steps=T, period=PERIOD, duty=0.5, load=0.5):
    """GRF (T, 4): each leg in contact for duty*period steps after its touchdown; leg j lags RF by rpd_j."""
    lags = [0] + [int(round(r / (2 * PI) * period)) for r in rpd]
    k = np.arange(n_steps)[:, None]
    contact = np.mod(k - np.array(lags), period) < duty * period
    return load * contact.astype(float)


def grf_from_touchdowns(td_lists, n_steps, stance=20, load=0.5):
    grf = np.zeros((n_steps, 4))
    for leg, tds in enumerate(td_lists):
        for t in tds:
            grf[t : t + stance, leg] = load
    return grf


def footfalls(rpd, freq=2.5, duty=0.5, n_steps=T, dt=DT, jitter=0, start=0.13, seed=0):
    """Ideal touchdown samples per leg: RF lands at start + k / freq, leg j lags it by rpd_j / (2 pi)
    of a cycle; each touchdown is moved by up to +-jitter samples. Returns (touchdowns, stance samples)."""
    rng = np.random.default_rng(seed)
    period = 1.0 / freq
    lags = np.concatenate([[0.0], np.asarray(rpd, float) / (2 * PI)]) * period
    out = []
    for lag in lags:
        t = start + lag + period * np.arange(-1, n_steps * dt / period + 1)
        k = np.round(t / dt).astype(int) + rng.integers(-jitter, jitter + 1, t.size)
        out.append(k[(k >= 0) & (k < n_steps)])
    return out, int(round(duty * period / dt))


def gait_grf(rpd, n_steps=T, bounce=False, load=0.5, **kw):
    """GRF (T, 4) of a gait from footfalls(); bounce=True adds a lift-off bounce to every stance: the
    force dips to the threshold for one sample and comes back for two before the foot leaves."""
    tds, stance = footfalls(rpd, n_steps=n_steps, **kw)
    grf = grf_from_touchdowns(tds, n_steps, stance, load)
    if bounce:
        for leg, ks in enumerate(tds):
            for k in ks:
                grf[k + stance - 3 : k + stance - 2, leg] = 0.1
                grf[k + stance : k + stance + 2, leg] = load
    return grf


# --- circular helpers -------------------------------------------------------------------------


def test_circular_difference_symmetric_and_bounded():
    rng = np.random.default_rng(0)
    a, b = rng.uniform(-10, 20, (2, 1000))
    d = circular_difference(a, b)
    assert np.allclose(d, circular_difference(b, a))
    assert (d >= 0).all() and (d <= PI + 1e-12).all()
    assert circular_difference(6.25, 0.03) == pytest.approx(2 * PI - 6.22)
    assert circular_difference(0.0, PI) == pytest.approx(PI)


def test_circular_mean_across_seam():
    assert circular_difference(circular_mean([6.25, 0.03]), 0.0) < 0.03
    assert circular_mean([1.0, 1.2]) == pytest.approx(1.1)
    m = circular_mean(np.array([[2 * PI - 0.1, 0.1, PI], [0.1, 2 * PI - 0.1, PI]]), axis=0)
    assert np.allclose(circular_difference(m, [0.0, 0.0, PI]), 0.0, atol=1e-9)


# --- classification ---------------------------------------------------------------------------


def test_ideal_gaits_table():
    assert set(IDEAL_GAITS) == {"trot", "pace", "bound", "pronk"}
    assert GAIT_LABELS[-1] == TRANSITION
    names = list(IDEAL_GAITS)
    for i, a in enumerate(names):
        assert classify_gait(IDEAL_GAITS[a]) == a
        for b in names[i + 1 :]:  # any two ideal gaits are pi*sqrt(2) apart
            d = np.linalg.norm(circular_difference(IDEAL_GAITS[a], IDEAL_GAITS[b]))
            assert d == pytest.approx(PI * math.sqrt(2))


def test_classify_wraps_around():
    assert classify_gait([6.25, 0.03, 6.25]) == "pronk"
    assert classify_gait([PI, PI, 2 * PI - 0.1]) == "trot"
    assert classify_gait([-PI, 3 * PI, 0.0]) == "trot"


def test_classify_threshold_and_odd_corners():
    for corner in ([PI, PI, PI], [PI, 0, 0], [0, PI, 0], [0, 0, PI]):
        assert classify_gait(corner) == TRANSITION
    assert classify_gait([PI - 2.0, PI, 0.0]) == "trot"  # exactly 2: not beyond
    assert classify_gait([PI - 2.01, PI, 0.0]) == TRANSITION
    assert classify_gait([PI - 2.01, PI, 0.0], max_distance=2.5) == "trot"
    assert classify_gait([np.nan, 0.0, 0.0]) == TRANSITION


def test_classify_batched():
    rpd = np.array([IDEAL_GAITS[g] for g in ("trot", "pace", "bound", "pronk")] + [[PI, PI, PI]])
    labels = classify_gait(rpd)
    assert labels.shape == (5,)
    assert labels.tolist() == ["trot", "pace", "bound", "pronk", TRANSITION]
    names, dist = classify(rpd.reshape(5, 1, 3))
    assert names.shape == dist.shape == (5, 1)
    assert dist[4, 0] == pytest.approx(PI)
    assert np.isnan(classify([np.nan, 0.0, 0.0])[1])


def test_uniform_rpd_transition_fraction():
    # Protocol §3: ~54 % of uniformly random RPDs lie within 2 of some gait.
    rng = np.random.default_rng(0)
    labels = classify_gait(rng.uniform(0, 2 * PI, (200_000, 3)))
    assert np.mean(labels != TRANSITION) == pytest.approx(0.540, abs=0.005)


# --- touchdowns and footfall phases -------------------------------------------------------------


def test_touchdowns_need_a_swing_before_them():
    grf = np.zeros((100, 4))
    grf[10:30, 0] = 0.4
    grf[36:40, 0] = 0.4  # after 0.06 s unloaded: a touchdown
    grf[50:52, 1] = 0.4
    grf[54:70, 1] = 0.4  # after 0.02 s unloaded (a lift-off bounce): none
    grf[0:20, 2] = 0.4  # contact at t = 0 is not a touchdown
    grf[40:60, 3] = 0.1  # exactly at threshold: not contact
    td = touchdowns(grf, DT)
    assert td[0].tolist() == [10, 36]
    assert td[1].tolist() == [50]
    assert td[2].tolist() == []
    assert td[3].tolist() == []
    assert touchdowns(grf, DT, min_swing=0.0)[1].tolist() == [50, 54]
    assert touchdowns(grf, DT, min_swing=0.1)[0].tolist() == [10]


GAIT_CASES = [(g, f, d) for g in ("trot", "pace", "bound", "pronk") for f, d in ((1.5, 0.6), (2.5, 0.5), (3.5, 0.35))]


@pytest.mark.parametrize("gait,freq,duty", GAIT_CASES)
def test_ideal_gaits_at_several_frequencies_and_duty_factors(gait, freq, duty):
    grf = gait_grf(IDEAL_GAITS[gait], freq=freq, duty=duty)
    td = touchdowns(grf, DT)
    expected = footfalls(IDEAL_GAITS[gait], freq=freq)[0]
    for leg in range(4):
        assert np.array_equal(td[leg], expected[leg][expected[leg] > 0])
    ts = rpd_timeseries(grf, DT)
    assert ts.times.tolist() == [5.0 * k for k in range(1, 9)]
    assert ts.valid.all()
    assert (ts.labels == gait).all()
    assert np.all(ts.distance < 2 * PI * 0.01 * freq * math.sqrt(3))  # within one-sample quantisation


@pytest.mark.parametrize("gait", ["trot", "pace", "bound", "pronk"])
def test_lift_off_bounce_is_no_touchdown(gait):
    clean, bouncy = gait_grf(IDEAL_GAITS[gait]), gait_grf(IDEAL_GAITS[gait], bounce=True)
    assert not np.array_equal(clean, bouncy)
    for a, b in zip(touchdowns(clean, DT), touchdowns(bouncy, DT)):
        assert np.array_equal(a, b)  # 100 per leg in 40 s, not 200
    assert (rpd_timeseries(bouncy, DT).labels == gait).all()
    # The old rule (a 0.1 s minimum interval instead of a swing) takes each bounce for a touchdown.
    assert len(touchdowns(bouncy, DT, min_swing=0.0)[0]) == 2 * len(touchdowns(clean, DT)[0])


@pytest.mark.parametrize("gait", ["trot", "pace", "bound", "pronk"])
def test_legs_landing_alternately_before_and_after_rf(gait):
    # Every leg with RPD 0 lands one sample before RF in even cycles and on RF's sample in odd ones
    # (so some RF cycles hold two of its touchdowns and some none); legs with RPD pi stay on time.
    tds, stance = footfalls(IDEAL_GAITS[gait])
    rf = tds[0]
    for j, r in enumerate(IDEAL_GAITS[gait]):
        if r == 0.0:
            tds[j + 1] = rf - (np.arange(rf.size) % 2 == 0)
    grf = grf_from_touchdowns(tds, T, stance)
    ts = rpd_timeseries(grf, DT)
    assert ts.valid.all()
    assert (ts.labels == gait).all()


@pytest.mark.parametrize("gait", ["trot", "pace", "bound", "pronk"])
def test_touchdown_jitter_of_two_samples(gait):
    for seed in range(3):
        ts = rpd_timeseries(gait_grf(IDEAL_GAITS[gait], jitter=2, seed=seed), DT)
        assert ts.valid.all()
        assert (ts.labels == gait).all()


@pytest.mark.parametrize("gait", ["trot", "pace", "bound", "pronk"])
def test_time_shift_leaves_labels_unchanged(gait):
    reference = rpd_timeseries(gait_grf(IDEAL_GAITS[gait]), DT).labels
    for start in (0.0, 0.07, 0.19, 0.33):
        assert np.array_equal(rpd_timeseries(gait_grf(IDEAL_GAITS[gait], start=start), DT).labels, reference)


def test_generic_rpd_value():
    rpd = (PI / 2, 3 * PI / 2, PI / 4)  # lags of 10, 30, 5 steps
    ts = rpd_timeseries(square_wave(rpd), DT)
    assert np.allclose(ts.rpd, rpd)


def test_pronk_with_jitter_across_seam():
    # Followers touch down every 40 steps; RF one step before them, then one slower RF cycle (42 steps)
    # lets the followers fall from "just after RF" (phase 2pi/42) to "just before the next RF"
    # (2pi*39/40). The last two cycles straddle the 0/2pi seam.
    followers = list(range(40, 500, 40))
    rf = list(range(39, 400, 40)) + [441, 481]
    grf = grf_from_touchdowns([rf, followers, followers, followers], 500)
    ff = footfall_phases(touchdowns(grf, DT))
    window = ff.phase[0][ff.cycle[0] >= len(rf) - 3]  # LF's touchdowns in the last two cycles
    assert np.allclose(np.sort(window), [2 * PI / 42, 2 * PI * 39 / 40, 2 * PI * 41 / 42])
    ts = rpd_timeseries(grf, DT)  # one checkpoint at 5 s: the last two cycles
    assert ts.labels.tolist() == ["pronk"]
    assert np.all(circular_difference(ts.rpd, 0.0) < 0.1)
    # An arithmetic mean of the same phases would sit near (pi, pi, pi), a Transition corner.
    assert classify_gait(np.full(3, np.mean(window))) == TRANSITION


def test_drifting_pattern_passes_through_transition():
    # RF, LF, RH trot at 2.5 Hz; LH runs at 2.525 Hz, so it gains one full cycle over 40 s and its RPD
    # sweeps 2pi -> 0: trot near the start and end, the odd corner (pi, pi, pi) around 20 s.
    grf = square_wave(IDEAL_GAITS["trot"])
    t = (np.arange(T) + 1) * 0.01
    grf[:, 3] = 0.5 * (np.mod(2.525 * t, 1.0) < 0.5)
    ts = rpd_timeseries(grf, DT)
    labels = ts.labels.tolist()
    assert labels[0] == "trot" and labels[-1] == "trot"
    assert labels[3] == TRANSITION  # t = 20 s
    assert ts.valid.all()
    lh = ts.rpd[:, 2]
    assert circular_difference(lh[3], PI) < 0.2
    assert np.all(np.diff(np.unwrap(lh)) < 0)  # LH keeps gaining on RF


def test_missing_or_dragging_leg_makes_window_invalid():
    grf = square_wave(IDEAL_GAITS["trot"])
    grf[:, 3] = 0.0  # three-legged: LH never touches down
    ts = rpd_timeseries(grf, DT)
    assert not ts.valid.any()
    assert (ts.labels == TRANSITION).all()
    grf[2000:, 3] = square_wave(IDEAL_GAITS["trot"])[2000:, 3]
    ts = rpd_timeseries(grf, DT)
    assert ts.valid.tolist() == [False] * 4 + [True] * 4
    assert ts.labels.tolist() == [TRANSITION] * 4 + ["trot"] * 4
    grf[:, 1] = 0.3 + 0.1 * (np.arange(T) % 40 < 20)  # LF drags: always loaded, never lands
    ts = rpd_timeseries(grf, DT)
    assert not ts.valid.any() and (ts.labels == TRANSITION).all()


def test_window_uses_last_two_complete_cycles():
    # RF touchdowns every 40 steps from 40; LF lags by 20 until step 2000, then by 10.
    rf = np.arange(40, 4000, 40)
    lf = np.where(rf < 2000, rf + 20, rf + 10)
    rpd = window_rpd(footfall_phases([rf, lf, rf, rf]), [1999, 2039, 2040, 2080, 30])
    assert np.isnan(rpd[4]).all() and not np.isnan(rpd[:4]).any()
    assert rpd[0, 0] == pytest.approx(PI)  # cycles [1880, 1920) and [1920, 1960)
    assert rpd[1, 0] == pytest.approx(PI)  # [2000, 2040) is not complete at sample 2039
    assert circular_difference(rpd[2, 0], 0.75 * PI) < 1e-9  # one cycle of each
    assert rpd[3, 0] == pytest.approx(PI / 2)
    assert np.allclose(rpd[:4, 1:], 0.0)  # RH, LH land with RF: phase 0 of the cycle they open


def test_slow_gait_without_two_cycles_is_invalid():
    grf = square_wave(IDEAL_GAITS["pace"], n_steps=1000, period=400)  # 0.25 Hz, first TD at 400
    ts = rpd_timeseries(grf, DT)
    assert ts.times.tolist() == [5.0, 10.0]
    assert ts.valid.tolist() == [False, False]  # RF cycles end at 800 only


def test_phase_and_contact_methods_agree():
    rng = np.random.default_rng(1)
    t = (np.arange(T) + 1) * 0.01
    rpd = np.array([2.0, 4.0, 0.5])
    offsets = np.concatenate([[rng.uniform(0, 2 * PI)], np.zeros(3)])
    offsets[1:] = offsets[0] - rpd
    phase = np.mod(2 * PI * 2.5 * t[:, None] + offsets, 2 * PI)
    grf = 0.3 * (phase >= PI)  # stance is [pi, 2pi)
    assert np.allclose(circular_difference(oscillator_rpd(phase), rpd), 0.0, atol=1e-9)
    td_phase, td_contact = phase_touchdowns(phase), touchdowns(grf, DT)
    for a, b in zip(td_phase, td_contact):
        # A touchdown within the first 0.05 s has no full swing on record: contacts skip it.
        assert np.array_equal(a[a >= 5], b)
    ts_c, ts_p = rpd_timeseries(grf, DT), rpd_timeseries(phase, DT, method="phase")
    assert np.allclose(ts_c.rpd, ts_p.rpd)
    assert agreement(ts_c.labels, ts_p.labels) == 1.0
    assert np.all(circular_difference(ts_c.rpd, rpd) < 2 * PI / 40 + 1e-9)  # one-step quantisation


def test_batched_timeseries_and_counts():
    gaits = ["trot", "pace", "bound", "pronk", "trot"]
    grf = np.stack([square_wave(IDEAL_GAITS[g]) for g in gaits])
    ts = rpd_timeseries(grf, DT)
    assert ts.rpd.shape == (5, 8, 3) and ts.labels.shape == (5, 8)
    assert ts.labels[:, 0].tolist() == gaits
    counts = gait_counts(ts.labels, axis=0)
    assert counts["trot"].tolist() == [2] * 8 and counts[TRANSITION].tolist() == [0] * 8
    with pytest.raises(ValueError):
        rpd_timeseries(grf[..., :3], DT)
