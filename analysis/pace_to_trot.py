"""Pace-to-trot transition: GRF of each foot against the RF oscillator phase (paper fig. "pacetotrot", §5).

Data: the ORC(111), sigma = 1 experiment of the gait-emergence study (analysis/gait_emergence.py),
first 10 s of one run that starts in pace and is trotting at 10 s. Run choice (the paper does not
say how it was picked): among runs whose first two complete cycles classify as pace and whose 10 s
checkpoint classifies as trot, the one starting closest to the ideal pace; if there is none, the run
minimising (distance of its start to pace + distance of its 10 s RPD to trot), reported as a fallback.

Figure: four polar panels (RF, LF, RH, LH); angle = phi_RF, radius = that leg's normalised GRF.
The trace is cut into complete RF cycles (at each wrap of phi_RF) coloured from blue (first) to
orange (last), first and last cycles bold. Red dots: the RF phase at which the panel's leg's own
oscillator wraps through 0; green dots: where it crosses pi (start of its stance half). Stance GRF
should lie between a green dot and the next red dot.

Usage: python -m analysis.pace_to_trot --runs DIR --out DIR [--quick]
"""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import numpy as np
from matplotlib.colors import LinearSegmentedColormap

from analysis import gait
from analysis.gait_emergence import EXPERIMENTS, first_cycles_rpd, pick_policies
from analysis.plotting import COLUMN_WIDTH, LEG_NAMES, paper_style, save_figure, write_csv
from analysis.rollout import EvalSettings, Job, cli_main, run_jobs
from gym_envs.oscillators import TWO_PI

import matplotlib.pyplot as plt  # noqa: E402  (after analysis.plotting selected the Agg backend)

PROTOCOL = {"runs": 500, "duration_s": 10.0}
QUICK = {"runs": 40, "duration_s": 10.0}
WINDOW_S = 10.0
FILE_STEM = "pace_to_trot"
CYCLE_CMAP = LinearSegmentedColormap.from_list("blue_orange", ["tab:blue", "tab:orange"])


def select_run(grf, dt: float, window_s: float = WINDOW_S) -> dict:
    """Pick the run to plot from GRF (N, T, 4); see the module docstring for the rule."""
    n_window = int(round(window_s / dt))
    grf = np.asarray(grf)[:, :n_window]
    initial = first_cycles_rpd(grf, dt)
    ts = gait.rpd_timeseries(grf, dt=dt)
    if ts.labels.shape[1] == 0:
        raise ValueError(f"pace_to_trot needs at least {gait.CHECKPOINT_INTERVAL:g} s of data")
    at_end = ts.rpd[:, -1]
    d_pace = gait.circular_distance(initial, gait.IDEAL_GAITS["pace"])
    d_trot = gait.circular_distance(at_end, gait.IDEAL_GAITS["trot"])
    start_labels = gait.classify_gait(initial)
    end_labels = ts.labels[:, -1]
    strict = np.flatnonzero((start_labels == "pace") & (end_labels == "trot"))
    if strict.size:
        idx = int(strict[np.argmin(d_pace[strict])])
        rule = "starts in pace, trots at the last checkpoint"
    else:
        score = np.where(np.isfinite(d_pace + d_trot), d_pace + d_trot, np.inf)
        if not np.isfinite(score).any():
            idx, rule = 0, "fallback: no run had two complete cycles; run 0 shown"
        else:
            idx = int(np.argmin(score))
            rule = "fallback: no pace-to-trot run; closest to pace at the start plus trot at the end"
    return {
        "index": idx,
        "rule": rule,
        "candidates": int(strict.size),
        "start_label": str(start_labels[idx]),
        "end_label": str(end_labels[idx]),
        "start_distance_to_pace": float(d_pace[idx]),
        "end_distance_to_trot": float(d_trot[idx]),
        "start_rpd": initial[idx],
        "end_rpd": at_end[idx],
        "end_time_s": float(ts.times[-1]),
    }


def crossings(phase_leg) -> tuple[np.ndarray, np.ndarray]:
    """Sample indices (from 1 on) where a phase series wraps through 0, and where it crosses pi upward."""
    p = np.asarray(phase_leg, float)
    zero = np.flatnonzero(p[1:] < p[:-1]) + 1
    pi = np.flatnonzero((p[:-1] < math.pi) & (p[1:] >= math.pi)) + 1
    return zero, pi


def collect(policies, quick: bool = False, settings: EvalSettings = EvalSettings(), seed: int = 0,
            progress: bool = True):
    """Simulate the ORC(111), sigma = 1 experiment for 10 s (when gait_emergence's data is not at hand)."""
    sizes = QUICK if quick else PROTOCOL
    policy = pick_policies(policies, seed).get("111")
    if policy is None:
        return None
    exp = next(e for e in EXPERIMENTS if e.key == "111_sigma1")
    steps = int(round(sizes["duration_s"] * policy.env_cfg.control.frequency_hz))
    (r,) = run_jobs([Job(policy, sizes["runs"])], steps, dataclasses.replace(settings, coupling=exp.coupling),
                    record=("grf", "phase", "terminated"), seed=seed, progress=progress, label="pace to trot")
    return policy, r


def run(policies, out_dir, quick: bool = False, settings: EvalSettings = EvalSettings(), seed: int = 0,
        progress: bool = True, source=None) -> dict:
    """Pick a pace-to-trot run, write its CSV and the polar figure; source = (policy, Rollout) to reuse."""
    if source is None:
        source = collect(policies, quick, settings, seed, progress)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if source is None:
        return {"files": {}, "skipped": "no ORC(111) policy among the runs"}
    policy, rollout = source
    n_window = int(round(WINDOW_S / rollout.dt))
    choice = select_run(rollout.data["grf"], rollout.dt)
    i = choice["index"]
    phase = rollout.data["phase"][i, :n_window]
    grf = rollout.data["grf"][i, :n_window]
    times = rollout.times[:n_window]

    csv_path = write_csv(out / f"{FILE_STEM}.csv",
                         ["time_s", *(f"phase_{leg}" for leg in LEG_NAMES), *(f"grf_{leg}" for leg in LEG_NAMES)],
                         ([f"{times[t]:.2f}", *(f"{v:.5f}" for v in phase[t]), *(f"{v:.5f}" for v in grf[t])]
                          for t in range(len(times))))

    with paper_style():
        fig = plot(phase, grf, title=f"run {i}: {choice['start_label']} at start, {choice['end_label']} at "
                                     f"{choice['end_time_s']:g} s")
    files = {"csv": csv_path, **save_figure(fig, out, FILE_STEM)}
    share = gait.stance_share(phase, grf)
    return {
        "files": files,
        "policy": policy.name,
        "run": i,
        "selection": {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in choice.items()},
        "stance_share": {leg: float(share[j]) for j, leg in enumerate(LEG_NAMES)},
        "fell": bool(rollout.data["terminated"][i, :n_window].any()) if "terminated" in rollout.data else None,
        "settings": settings.describe(),
    }


def plot(phase, grf, title: str = ""):
    """2x2 polar panels of GRF_j against phi_RF, cycles coloured first (blue) to last (orange)."""
    phase, grf = np.asarray(phase, float), np.asarray(grf, float)
    rf = phase[:, 0]
    wraps = np.flatnonzero(rf[1:] < rf[:-1]) + 1  # first sample of each new RF cycle
    cycles = list(zip(wraps[:-1], wraps[1:]))  # complete cycles only
    fig, axes = plt.subplots(2, 2, figsize=(COLUMN_WIDTH, 3.9), subplot_kw={"projection": "polar"},
                             layout="constrained")
    for j, ax in enumerate(axes.flat):
        r_max = float(grf[:, j].max()) if grf[:, j].max() > 0 else 1.0
        for c, (a, b) in enumerate(cycles):
            frac = c / max(len(cycles) - 1, 1)
            bold = c in (0, len(cycles) - 1)
            # Close the cycle at 2pi: append the RF phase of the next sample unwrapped by one turn.
            angle = np.append(rf[a:b], rf[b] + TWO_PI)
            radius = np.append(grf[a:b, j], grf[b, j])
            ax.plot(angle, radius, color=CYCLE_CMAP(frac), lw=1.6 if bold else 0.5, alpha=1.0 if bold else 0.7,
                    zorder=3 if bold else 2)
        zero, pi = crossings(phase[:, j])
        dot_r = 1.08 * r_max
        ax.plot(rf[zero], np.full(zero.size, dot_r), "o", color="tab:red", ms=2.2, zorder=4, clip_on=False)
        ax.plot(rf[pi], np.full(pi.size, dot_r), "o", color="tab:green", ms=2.2, zorder=4, clip_on=False)
        ax.set_ylim(0, 1.15 * r_max)
        ax.set_title(f"{LEG_NAMES[j]} foot", pad=4)
        ax.set_xticks(np.arange(4) * math.pi / 2)
        ax.set_xticklabels(["0", r"$\pi/2$", r"$\pi$", r"$3\pi/2$"])
        ax.set_yticks(_radial_ticks(r_max))
        ax.set_rlabel_position(112.5)
        ax.tick_params(axis="y", labelsize=5, pad=0)
        ax.grid(lw=0.3)
    handles = [
        plt.Line2D([], [], color=CYCLE_CMAP(0.0), lw=1.6, label="first cycle"),
        plt.Line2D([], [], color=CYCLE_CMAP(1.0), lw=1.6, label="last cycle"),
        plt.Line2D([], [], ls="", marker="o", color="tab:red", ms=3, label=r"leg's $\phi$ wraps 0"),
        plt.Line2D([], [], ls="", marker="o", color="tab:green", ms=3, label=r"leg's $\phi$ crosses $\pi$"),
    ]
    fig.legend(handles=handles, loc="outside lower center", ncols=2, frameon=False)
    fig.suptitle(r"GRF [BW] (radius) vs. RF oscillator phase $\phi_{RF}$ [rad] (angle)" + (f"\n{title}" if title
                 else ""), fontsize=7)
    return fig


def _radial_ticks(r_max: float) -> list[float]:
    step = 0.1 if r_max <= 0.4 else 0.2 if r_max <= 0.8 else 0.5
    return list(np.arange(1, int(r_max / step + 1e-9) + 1) * step)


def main(argv=None) -> int:
    return cli_main("analysis.pace_to_trot", __doc__, run, argv)


if __name__ == "__main__":
    sys.exit(main())
