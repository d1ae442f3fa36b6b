"""Gait metrics: touchdowns, relative phase differences (RPD) and gait classification.

Follows analysis protocol §3 as corrected (paper Sec. II-A). Pure numpy, no simulator. Inputs are
logged once per control step: GRF arrays of shape (T, 4) (or (N, T, 4) for N robots), legs ordered
RF, LF, RH, LH, GRF normalised by body weight. Sample k is taken at time (k + 1) * dt.

Definitions (the paper leaves the first three open; they are reproduction choices):
- touchdown (contact method): GRF rises above 0.1 body weight after the foot was unloaded
  (GRF <= 0.1) for at least MIN_SWING_TIME. The hysteresis rejects a force that dips to the
  threshold and rises again as the foot leaves the ground, which a minimum interval between
  touchdowns cannot (one stance lasts longer than any interval short enough to keep real steps).
  Phase method: the oscillator phase passes pi (the start of its stance half).
- RF touchdowns t_0 < t_1 < ... bound the gait cycles. Every touchdown tau of leg j in LF, RH, LH gets
  the phase 2*pi*(tau - t_k)/(t_{k+1} - t_k) in the cycle [t_k, t_{k+1}) that contains it. A window's
  RPD of leg j is the circular mean of the phases of its touchdowns in the window, so a leg landing
  in phase with RF (a sample before RF in one cycle, on the same sample in the next) is measured
  right although some cycles hold two of its touchdowns and some none.
- checkpoints every 5 s: the window is the last two complete RF cycles ending at or before it. A
  window with fewer than two cycles, or in which some leg never touched down (held up, dragging), is
  invalid: labelled 'transition' and counted apart (GaitTimeseries.valid).
- distance: wrapped per component, then the Euclidean norm over (LF, RH, LH); nearest ideal gait,
  'transition' beyond 2 (gym_envs.oscillators.classify_rpd, shared with the training diagnostics).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import torch

from gym_envs import oscillators
from gym_envs.oscillators import TWO_PI

CONTACT_THRESHOLD = 0.1  # body weights (protocol §3: the codebase's only contact threshold)
MIN_SWING_TIME = 0.05  # s the foot must be unloaded before a rise counts as a touchdown
CHECKPOINT_INTERVAL = 5.0  # s
CYCLES_PER_CHECKPOINT = 2
TRANSITION_DISTANCE = oscillators.TRANSITION_DISTANCE

# RPD of (LF, RH, LH) relative to RF: paper Sec. II-A, protocol §3.
IDEAL_GAITS = {name: np.array(rpd) for name, rpd in oscillators.IDEAL_RPD.items()}
TRANSITION = "transition"
GAIT_LABELS = tuple(IDEAL_GAITS) + (TRANSITION,)
_LABEL_NAMES = np.array(GAIT_LABELS, dtype="<U10")


# --- angles -----------------------------------------------------------------------------------


def circular_difference(a, b):
    """Per-component wrapped distance in [0, pi]: min(|a-b| mod 2pi, 2pi - |a-b| mod 2pi)."""
    d = np.mod(np.abs(np.asarray(a, float) - np.asarray(b, float)), TWO_PI)
    return np.minimum(d, TWO_PI - d)


def circular_distance(a, b):
    """Euclidean norm over the last axis of the per-component wrapped differences."""
    return np.sqrt(np.sum(circular_difference(a, b) ** 2, axis=-1))


def circular_mean(angles, axis=0):
    """atan2(sum sin, sum cos) mod 2pi; unlike the arithmetic mean it works across the 0/2pi seam.

    Undefined when the samples cancel (e.g. 0 and pi); atan2 then returns an arbitrary angle.
    """
    angles = np.asarray(angles, float)
    m = np.mod(np.arctan2(np.sin(angles).sum(axis=axis), np.cos(angles).sum(axis=axis)), TWO_PI)
    return np.where(m >= TWO_PI, 0.0, m)


# --- touchdowns -------------------------------------------------------------------------------


def touchdowns(grf, dt, threshold=CONTACT_THRESHOLD, min_swing=MIN_SWING_TIME):
    """Touchdown sample indices per leg (list of 4 int arrays) from a (T, 4) GRF array sampled every dt [s].

    A touchdown is a sample t with GRF[t] > threshold after at least min_swing [s] of samples with
    GRF <= threshold (the unloaded stretch may begin with the record). A contact at t = 0 is none.
    """
    grf = np.asarray(grf, float)
    if grf.ndim != 2 or grf.shape[1] != 4:
        raise ValueError(f"expected GRF of shape (T, 4), got {grf.shape}")
    contact = grf > threshold
    steps = np.arange(len(grf))[:, None]
    # Index of the latest loaded sample at or before each t (-1 before the first one).
    last_loaded = np.maximum.accumulate(np.where(contact, steps, -1), axis=0)
    swing = steps[1:] - 1 - last_loaded[:-1]  # unloaded samples right before sample t = 1 .. T-1
    min_samples = int(math.ceil(min_swing / dt - 1e-9))
    rises = contact[1:] & (swing >= max(min_samples, 1))
    return [np.flatnonzero(rises[:, i]) + 1 for i in range(4)]


def phase_touchdowns(phase):
    """Touchdown indices per leg from oscillator phases (T, 4): steps where phi passes pi upward."""
    phase = np.asarray(phase, float)
    prev, cur = phase[:-1], phase[1:]
    step = np.mod(cur - prev, TWO_PI)
    # A forward step of less than pi from below pi that reaches pi; wraps 2pi -> 0 never qualify.
    crossed = (prev < math.pi) & (step < math.pi) & (prev + step >= math.pi)
    return [np.flatnonzero(crossed[:, i]) + 1 for i in range(phase.shape[1])]


def stance_share(phase, grf) -> np.ndarray:
    """Per leg, the share of its GRF impulse that falls in its own oscillator's stance half [pi, 2pi).

    phase, grf: (..., T, 4); sums over the time axis. NaN for a leg that never carried load.
    """
    phase, grf = np.asarray(phase, float), np.asarray(grf, float)
    total = grf.sum(axis=-2)
    in_stance = (grf * (phase >= math.pi)).sum(axis=-2)
    return np.divide(in_stance, total, out=np.full(total.shape, np.nan), where=total > 0)


def oscillator_rpd(phase):
    """Instantaneous oscillator RPD (..., 3): (phi_RF - phi_j) mod 2pi for j = LF, RH, LH."""
    phase = np.asarray(phase, float)
    return np.mod(phase[..., :1] - phase[..., 1:], TWO_PI)


# --- footfall phases and RPD ------------------------------------------------------------------


class Footfalls(NamedTuple):
    rf: np.ndarray  # (K + 1,) RF touchdown samples; cycle k is [rf[k], rf[k + 1])
    cycle: tuple[np.ndarray, np.ndarray, np.ndarray]  # per leg LF, RH, LH: cycle of each touchdown
    phase: tuple[np.ndarray, np.ndarray, np.ndarray]  # per leg: its phase in that cycle, [0, 2pi)


def footfall_phases(touchdown_steps) -> Footfalls:
    """Place every LF, RH and LH touchdown in the RF cycle that contains it (touchdowns outside every
    complete cycle are dropped)."""
    rf = np.asarray(touchdown_steps[0], dtype=int)
    cycles, phases = [], []
    for j in range(1, 4):
        td = np.asarray(touchdown_steps[j], dtype=int)
        k = np.searchsorted(rf, td, side="right") - 1
        inside = (k >= 0) & (k < rf.size - 1)
        td, k = td[inside], k[inside]
        cycles.append(k)
        phases.append(TWO_PI * (td - rf[k]) / (rf[k + 1] - rf[k]) if k.size else np.zeros(0))
    return Footfalls(rf, tuple(cycles), tuple(phases))


def window_rpd(footfalls: Footfalls, last_samples, n_cycles=CYCLES_PER_CHECKPOINT):
    """RPD (C, 3) over the last n_cycles complete RF cycles ending at or before each sample index.

    Rows are NaN where the window is invalid: fewer than n_cycles cycles, or a leg without touchdown.
    """
    last_samples = np.atleast_1d(np.asarray(last_samples))
    out = np.full((last_samples.size, 3), np.nan)
    n_done = np.searchsorted(footfalls.rf, last_samples, side="right") - 1  # cycles complete by then
    for c, n in enumerate(n_done):
        if n < n_cycles:
            continue
        for j in range(3):
            in_window = (footfalls.cycle[j] >= n - n_cycles) & (footfalls.cycle[j] < n)
            if in_window.any():
                out[c, j] = circular_mean(footfalls.phase[j][in_window])
    return out


class GaitTimeseries(NamedTuple):
    times: np.ndarray  # (C,) checkpoint times [s]
    rpd: np.ndarray  # (C, 3) or (N, C, 3); NaN where invalid
    valid: np.ndarray  # (C,) or (N, C): two complete cycles in which every leg touched down
    labels: np.ndarray  # (C,) or (N, C) gait names (GAIT_LABELS); invalid windows are 'transition'
    distance: np.ndarray  # (C,) or (N, C) distance to the nearest ideal gait (NaN where invalid)


def rpd_timeseries(signal, dt, interval=CHECKPOINT_INTERVAL, method="contact"):
    """RPD and gait label every `interval` s (checkpoints interval, 2*interval, ... <= T*dt).

    signal: GRF (method='contact') or oscillator phases (method='phase'), shape (T, 4) or (N, T, 4), sampled
    every dt [s] (the rollout's control step, `Rollout.dt`).
    """
    x = np.asarray(signal, float)
    batched = x.ndim == 3
    if not batched:
        x = x[None]
    if x.ndim != 3 or x.shape[2] != 4:
        raise ValueError(f"expected shape (T, 4) or (N, T, 4), got {np.shape(signal)}")
    if method not in ("contact", "phase"):
        raise ValueError(f"unknown method {method!r}; use 'contact' or 'phase'")
    n_steps = x.shape[1]
    n_check = int(math.floor(n_steps * dt / interval + 1e-9))
    times = interval * np.arange(1, n_check + 1)
    # Sample k is at (k + 1) * dt: the last sample logged by time t is t / dt - 1.
    last_sample = np.floor(times / dt + 1e-6).astype(int) - 1

    rpd = np.full((x.shape[0], n_check, 3), np.nan)
    for n in range(x.shape[0]):
        td = touchdowns(x[n], dt) if method == "contact" else phase_touchdowns(x[n])
        rpd[n] = window_rpd(footfall_phases(td), last_sample)
    valid = ~np.isnan(rpd).any(axis=-1)
    labels, distance = classify(rpd)
    if not batched:
        rpd, valid, labels, distance = rpd[0], valid[0], labels[0], distance[0]
    return GaitTimeseries(times, rpd, valid, labels, distance)


# --- classification ---------------------------------------------------------------------------


def classify(rpd, max_distance=TRANSITION_DISTANCE):
    """(labels, distances) for RPD vectors (..., 3): the nearest ideal gait's name, or 'transition'
    beyond max_distance or for a NaN (invalid) RPD, and the distance to the nearest gait (NaN if invalid)."""
    idx, dist = oscillators.classify_rpd(torch.as_tensor(np.asarray(rpd, float), device="cpu"), max_distance)
    return _LABEL_NAMES[idx.numpy()], dist.numpy()


def classify_gait(rpd, max_distance=TRANSITION_DISTANCE):
    """Gait name for an RPD (3,) -> str, or (..., 3) -> array of str (see `classify`)."""
    labels, _ = classify(rpd, max_distance)
    return str(labels) if np.ndim(rpd) == 1 else labels


def gait_counts(labels, axis=0):
    """Count each label of GAIT_LABELS along `axis` (e.g. robots), e.g. for the gait-distribution plot."""
    labels = np.asarray(labels)
    return {g: np.sum(labels == g, axis=axis) for g in GAIT_LABELS}


def label_shares(labels) -> dict[str, float]:
    """Share of each label present in a 1-D array of labels (e.g. one per robot)."""
    labels = np.asarray(labels)
    return {str(g): float(np.mean(labels == g)) for g in sorted(set(labels.tolist()))}


def mix_text(shares: dict[str, float], alike: bool = False) -> str:
    """'pronk 56%, transition 44%' (largest first), or 'all robots alike: pronk' when the robots are
    one sample repeated (Rollout.robots_alike)."""
    if alike:
        return "all robots alike: " + ", ".join(g for g, p in shares.items() if p > 0)
    items = sorted(((p, g) for g, p in shares.items() if p > 0), reverse=True)
    return ", ".join(f"{g} {p:.0%}" for p, g in items) or "-"


def agreement(labels_a, labels_b, axis=None):
    """Share of entries on which two labellings (e.g. contact- and phase-based) agree."""
    return np.mean(np.asarray(labels_a) == np.asarray(labels_b), axis=axis)
