"""Gait metrics: touchdowns, relative phase differences (RPD) and gait classification.

Follows analysis protocol §3 (paper Sec. II-A). Pure numpy, no simulator. Inputs are logged once per
control step: GRF arrays of shape (T, 4) (or (N, T, 4) for N robots), legs ordered RF, LF, RH, LH,
GRF normalised by body weight. Sample k is taken at time (k + 1) * dt, i.e. right after control
step k + 1, as the protocols log.

Definitions used (the paper leaves the first four open; they are reproduction choices):
- touchdown: contact c = GRF > 0.1 switches 0 -> 1; a touchdown less than 0.1 s after the previous
  accepted one of the same leg is chatter and ignored. Oscillator-based alternative: phi passes pi.
- gait cycle k: from RF touchdown t_k to t_{k+1}. RPD_j = 2*pi*(tau_j - t_k)/(t_{k+1} - t_k) in
  [0, 2*pi), tau_j the first touchdown of leg j in [t_k, t_{k+1}); a cycle without one is invalid.
- checkpoints every 5 s: circular mean of the RPD of the last two complete cycles ending at or before
  the checkpoint; a checkpoint with fewer than two cycles or an invalid cycle is invalid.
- distance: wrapped per component, delta(a, b) = min(|a-b| mod 2pi, 2pi - |a-b| mod 2pi), then the
  Euclidean norm over (LF, RH, LH). Nearest ideal gait, 'transition' if the distance exceeds 2
  (paper: "exceeds 2", so exactly 2 still counts as the gait). Invalid/NaN RPD -> 'transition'.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

TWO_PI = 2.0 * math.pi
DT = 0.01  # control step [s]
CONTACT_THRESHOLD = 0.1  # body weights (protocol §3: the codebase's only contact threshold)
MIN_TOUCHDOWN_INTERVAL = 0.1  # s, chatter rejection
CHECKPOINT_INTERVAL = 5.0  # s
CYCLES_PER_CHECKPOINT = 2
TRANSITION_DISTANCE = 2.0

# RPD of (LF, RH, LH) relative to RF: paper Sec. II-A, protocol §3.
IDEAL_GAITS = {
    "trot": np.array([math.pi, math.pi, 0.0]),
    "pace": np.array([math.pi, 0.0, math.pi]),
    "bound": np.array([0.0, math.pi, math.pi]),
    "pronk": np.array([0.0, 0.0, 0.0]),
}
TRANSITION = "transition"
GAIT_LABELS = tuple(IDEAL_GAITS) + (TRANSITION,)
_IDEAL_MATRIX = np.stack(list(IDEAL_GAITS.values()))  # (4 gaits, 3)
_IDEAL_NAMES = np.array(list(IDEAL_GAITS), dtype="<U10")


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


def touchdowns(grf, threshold=CONTACT_THRESHOLD, dt=DT, min_interval=MIN_TOUCHDOWN_INTERVAL):
    """Touchdown sample indices per leg (list of 4 int arrays) from a (T, 4) GRF array.

    A touchdown is a step t with GRF[t] > threshold and GRF[t-1] <= threshold (a contact at t = 0 is
    not one). Touchdowns closer than min_interval [s] to the previous accepted one are dropped.
    """
    grf = np.asarray(grf, float)
    if grf.ndim != 2 or grf.shape[1] != 4:
        raise ValueError(f"expected GRF of shape (T, 4), got {grf.shape}")
    contact = grf > threshold
    rises = contact[1:] & ~contact[:-1]
    return [_debounce(np.flatnonzero(rises[:, i]) + 1, dt, min_interval) for i in range(4)]


def phase_touchdowns(phase):
    """Touchdown indices per leg from oscillator phases (T, 4): steps where phi passes pi upward."""
    phase = np.asarray(phase, float)
    prev, cur = phase[:-1], phase[1:]
    step = np.mod(cur - prev, TWO_PI)
    # A forward step of less than pi from below pi that reaches pi; wraps 2pi -> 0 never qualify.
    crossed = (prev < math.pi) & (step < math.pi) & (prev + step >= math.pi)
    return [np.flatnonzero(crossed[:, i]) + 1 for i in range(phase.shape[1])]


def oscillator_rpd(phase):
    """Instantaneous oscillator RPD (..., 3): (phi_RF - phi_j) mod 2pi for j = LF, RH, LH."""
    phase = np.asarray(phase, float)
    return np.mod(phase[..., :1] - phase[..., 1:], TWO_PI)


def _debounce(idx, dt, min_interval):
    if min_interval <= 0 or idx.size < 2:
        return idx
    keep, last = [], None
    for i in idx:
        if last is None or (i - last) * dt >= min_interval - 1e-9:
            keep.append(i)
            last = i
    return np.asarray(keep, dtype=int)


# --- cycles and RPD ---------------------------------------------------------------------------


class GaitCycles(NamedTuple):
    start: np.ndarray  # (K,) RF touchdown index opening each cycle
    end: np.ndarray  # (K,) next RF touchdown index
    rpd: np.ndarray  # (K, 3) RPD of LF, RH, LH in [0, 2pi); NaN where the leg did not touch down


def relative_phase_differences(touchdown_steps):
    """Per-cycle RPD from per-leg touchdown indices (as returned by touchdowns())."""
    rf = np.asarray(touchdown_steps[0], dtype=int)
    start, end = rf[:-1], rf[1:]
    rpd = np.full((start.size, 3), np.nan)
    if start.size == 0:
        return GaitCycles(start, end, rpd)
    period = (end - start).astype(float)
    for j in range(3):
        td = np.asarray(touchdown_steps[j + 1], dtype=int)
        if td.size == 0:
            continue
        pos = np.searchsorted(td, start, side="left")  # first touchdown at or after t_k
        ok = pos < td.size
        tau = np.where(ok, td[np.minimum(pos, td.size - 1)], -1)
        ok &= tau < end
        rpd[ok, j] = TWO_PI * (tau[ok] - start[ok]) / period[ok]
    return GaitCycles(start, end, rpd)


def checkpoint_rpd(cycles: GaitCycles, checkpoint_steps, n_cycles=CYCLES_PER_CHECKPOINT):
    """Circular mean RPD of the last n_cycles complete cycles with end <= each checkpoint index.

    Returns (rpd (C, 3) with NaN rows where invalid, valid (C,) bool).
    """
    checkpoint_steps = np.atleast_1d(np.asarray(checkpoint_steps))
    out = np.full((checkpoint_steps.size, 3), np.nan)
    n_done = np.searchsorted(cycles.end, checkpoint_steps, side="right")  # cycles ending at/before
    for c, n in enumerate(n_done):
        if n < n_cycles:
            continue
        window = cycles.rpd[n - n_cycles : n]
        if np.isnan(window).any():
            continue
        out[c] = circular_mean(window, axis=0)
    return out, ~np.isnan(out).any(axis=1)


class GaitTimeseries(NamedTuple):
    times: np.ndarray  # (C,) checkpoint times [s]
    rpd: np.ndarray  # (C, 3) or (N, C, 3); NaN where invalid
    valid: np.ndarray  # (C,) or (N, C): enough complete cycles, every leg touched down
    labels: np.ndarray  # (C,) or (N, C) gait names (GAIT_LABELS)
    distance: np.ndarray  # (C,) or (N, C) distance to the nearest ideal gait (NaN where invalid)


def rpd_timeseries(
    signal,
    dt=DT,
    interval=CHECKPOINT_INTERVAL,
    n_cycles=CYCLES_PER_CHECKPOINT,
    method="contact",
    threshold=CONTACT_THRESHOLD,
    min_interval=MIN_TOUCHDOWN_INTERVAL,
    max_distance=TRANSITION_DISTANCE,
):
    """RPD and gait label every `interval` s (checkpoints interval, 2*interval, ... <= T*dt).

    signal: GRF (method='contact') or oscillator phases (method='phase'), shape (T, 4) or (N, T, 4).
    Each checkpoint averages the last n_cycles complete RF cycles ending at or before it.
    """
    x = np.asarray(signal, float)
    batched = x.ndim == 3
    if not batched:
        x = x[None]
    if x.ndim != 3 or x.shape[2] != 4:
        raise ValueError(f"expected shape (T, 4) or (N, T, 4), got {np.shape(signal)}")
    n_steps = x.shape[1]
    n_check = int(math.floor(n_steps * dt / interval + 1e-9))
    times = interval * np.arange(1, n_check + 1)
    # Sample k is at (k + 1) * dt, so a cycle ending at sample `end` is complete by (end + 1) * dt.
    last_sample = np.floor(times / dt + 1e-6).astype(int) - 1

    rpd = np.full((x.shape[0], n_check, 3), np.nan)
    for n in range(x.shape[0]):
        if method == "contact":
            td = touchdowns(x[n], threshold, dt, min_interval)
        elif method == "phase":
            td = phase_touchdowns(x[n])
        else:
            raise ValueError(f"unknown method {method!r}; use 'contact' or 'phase'")
        rpd[n], _ = checkpoint_rpd(relative_phase_differences(td), last_sample, n_cycles)
    valid = ~np.isnan(rpd).any(axis=-1)
    labels, distance = nearest_gait(rpd)
    labels = np.where(valid & (distance <= max_distance), labels, TRANSITION)
    if not batched:
        rpd, valid, labels, distance = rpd[0], valid[0], labels[0], distance[0]
    return GaitTimeseries(times, rpd, valid, labels, distance)


# --- classification ---------------------------------------------------------------------------


def gait_distances(rpd):
    """Wrapped distances (..., 4) from RPD vectors (..., 3) to the ideal gaits, in IDEAL_GAITS order."""
    rpd = np.asarray(rpd, float)
    return circular_distance(rpd[..., None, :], _IDEAL_MATRIX)


def nearest_gait(rpd):
    """(names, distances) of the nearest ideal gait for RPD vectors (..., 3); NaN rows give NaN."""
    d = gait_distances(rpd)
    nan = np.isnan(d).any(axis=-1)
    idx = np.argmin(np.where(np.isnan(d), np.inf, d), axis=-1)
    dist = np.where(nan, np.nan, np.take_along_axis(d, idx[..., None], axis=-1)[..., 0])
    return _IDEAL_NAMES[idx], dist


def classify_gait(rpd, max_distance=TRANSITION_DISTANCE):
    """Nearest ideal gait name, or 'transition' if its wrapped distance exceeds max_distance.

    Distance: per component delta = min(|a-b| mod 2pi, 2pi - |a-b| mod 2pi), then the Euclidean
    norm over (LF, RH, LH). Accepts (3,) -> str, or (..., 3) -> array of str. NaN -> 'transition'.
    """
    rpd = np.asarray(rpd, float)
    names, dist = nearest_gait(rpd)
    labels = np.where(dist <= max_distance, names, TRANSITION)  # NaN compares False
    return str(labels) if rpd.ndim == 1 else labels


def gait_counts(labels, axis=0):
    """Count each label of GAIT_LABELS along `axis` (e.g. robots), e.g. for the gait-distribution plot."""
    labels = np.asarray(labels)
    return {g: np.sum(labels == g, axis=axis) for g in GAIT_LABELS}
