"""Emergence of gaits (paper figs. "rpdPlots", "gait111eval111", "gait110eval111"; protocol §3, §4).

Three experiments, each one policy picked at random (seeded) from its configuration, many runs with
i.i.d. random initial phases, 40 s at a 1 m/s forward command:
  a) ORC(111) evaluated with coupling sigma = 0,
  b) the same ORC(111) policy with sigma = 1 (as trained),
  c) an ORC(110) policy with sigma = 1 (coupling it never saw in training).
The relative phase difference (RPD) of LF, RH, LH to RF comes from foot touchdowns (contact-based,
analysis/gait.py: GRF > 0.1 BW after >= 0.05 s unloaded), each touchdown placed in its RF cycle and
circularly averaged over the last two complete RF cycles at every 5 s checkpoint and classified as the nearest ideal gait, or Transition beyond distance 2.
The oscillator-based RPD (phi passing pi) is computed beside it as a check.

Initial RPD: the circular mean over the first two complete RF cycles (the same definition as the
final one); the initial oscillator offsets (phi_RF(0) - phi_j(0)) are stored too.
Settling time: the first checkpoint at which at least 90 % of the runs already show the gait label
they end with. All experiments use the same seed, so their runs start from the same initial phases.

Usage: python -m analysis.gait_emergence --runs DIR --out DIR [--quick]
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis import gait
from analysis.plotting import COLUMN_WIDTH, GAIT_COLORS, WIDE_WIDTH, paper_style, save_figure, write_csv
from analysis.rollout import EvalSettings, Job, cli_main, group_by_orc, run_jobs

import matplotlib.pyplot as plt  # noqa: E402  (after analysis.plotting selected the Agg backend)

PROTOCOL = {"runs": 500, "duration_s": 40.0}
QUICK = {"runs": 40, "duration_s": 15.0}
COMMAND = (1.0, 0.0, 0.0)  # 1 m/s forward
SETTLED_FRACTION = 0.9
FILE_STEM = "gait_emergence"
GAITS = gait.GAIT_LABELS  # trot, pace, bound, pronk, transition
RPD_NAMES = ("LF", "RH", "LH")


@dataclass(frozen=True)
class Experiment:
    key: str
    orc: str  # configuration the policy was trained in
    coupling: float  # moving sigma at evaluation
    title: str


EXPERIMENTS = (
    Experiment("111_sigma0", "111", 0.0, r"a) ORC(111), $\sigma$ = 0"),
    Experiment("111_sigma1", "111", 1.0, r"b) ORC(111), $\sigma$ = 1"),
    Experiment("110_sigma1", "110", 1.0, r"c) ORC(110), $\sigma$ = 1"),
)


def pick_policies(policies, seed: int = 0) -> dict:
    """One policy per trained configuration used here, chosen at random; a) and b) share theirs."""
    rng = np.random.default_rng(seed)
    groups = group_by_orc(policies)
    return {orc: groups[orc][int(rng.integers(len(groups[orc])))] for orc in sorted({e.orc for e in EXPERIMENTS})
            if groups.get(orc)}


def collect(policies, quick: bool = False, settings: EvalSettings = EvalSettings(), seed: int = 0,
            progress: bool = True) -> dict:
    """Simulate every experiment whose configuration is present: {key: (Experiment, policy, Rollout)}."""
    sizes = QUICK if quick else PROTOCOL
    chosen = pick_policies(policies, seed)
    out = {}
    for exp in EXPERIMENTS:
        policy = chosen.get(exp.orc)
        if policy is None:
            continue
        steps = int(round(sizes["duration_s"] * policy.env_cfg.control.frequency_hz))
        exp_settings = dataclasses.replace(settings, coupling=exp.coupling)
        (r,) = run_jobs([Job(policy, sizes["runs"])], steps, exp_settings, command=COMMAND,
                        record=("grf", "phase", "terminated"), seed=seed, progress=progress,
                        label=f"gait emergence {exp.key}")
        out[exp.key] = (exp, policy, r)
    return out


def first_cycles_rpd(grf_runs, dt: float) -> np.ndarray:
    """Contact RPD averaged over each run's first two complete RF cycles: (N, T, 4) -> (N, 3), NaN if none."""
    out = np.full((len(grf_runs), 3), np.nan)
    for n, grf in enumerate(grf_runs):
        footfalls = gait.footfall_phases(gait.touchdowns(grf, dt=dt))
        if len(footfalls.rf) > gait.CYCLES_PER_CHECKPOINT:
            out[n] = gait.window_rpd(footfalls, footfalls.rf[gait.CYCLES_PER_CHECKPOINT])[0]
    return out


def settling_time(times, labels, fraction: float = SETTLED_FRACTION) -> float:
    """First checkpoint time at which >= fraction of runs show their final label (labels (N, C))."""
    labels = np.asarray(labels)
    if labels.size == 0:
        return float("nan")
    agree = (labels == labels[:, -1:]).mean(axis=0)
    return float(np.asarray(times)[np.argmax(agree >= fraction)])


def analyse(rollout, dt: float | None = None) -> dict:
    """RPD time series, labels, counts and summary numbers of one experiment's rollout."""
    dt = dt or rollout.dt
    grf, phase = rollout.data["grf"], rollout.data["phase"]
    contact = gait.rpd_timeseries(grf, dt=dt)
    if contact.times.size == 0 or len(grf) == 0:
        raise ValueError(f"gait emergence needs runs of at least {gait.CHECKPOINT_INTERVAL:g} s")
    by_phase = gait.rpd_timeseries(phase, dt=dt, method="phase")
    initial = first_cycles_rpd(grf, dt)
    initial_labels = gait.classify_gait(initial)
    offsets = gait.oscillator_rpd(rollout.initial_phase)
    counts = gait.gait_counts(contact.labels, axis=0)  # gait -> (C,)
    final, final_labels = contact.rpd[:, -1], contact.labels[:, -1]
    n = len(grf)
    return {
        "times": contact.times,
        "contact": contact,
        "phase": by_phase,
        "initial_rpd": initial,
        "initial_labels": initial_labels,
        "initial_offsets": offsets,
        "final_rpd": final,
        "final_labels": final_labels,
        "counts": counts,
        "invalid": (~contact.valid).sum(axis=0),
        "settling_time_s": settling_time(contact.times, contact.labels),
        "final_fractions": {g: float(np.mean(final_labels == g)) for g in GAITS},
        # Agreement of the two touchdown definitions at the last checkpoint.
        "contact_phase_label_agreement": float(np.mean(final_labels == by_phase.labels[:, -1])),
        "contact_phase_median_distance": _nanmedian(gait.circular_distance(final, by_phase.rpd[:, -1])),
        # How far runs moved in RPD space from the first two cycles to the end.
        "median_initial_final_distance": _nanmedian(gait.circular_distance(initial, final)),
        "falls": int(rollout.fell().sum()),
        "runs": n,
    }


def _nanmedian(x) -> float:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(np.median(x)) if x.size else float("nan")


def run(policies, out_dir, quick: bool = False, settings: EvalSettings = EvalSettings(), seed: int = 0,
        progress: bool = True, collected: dict | None = None) -> dict:
    """Simulate (or take `collected` from collect()), write CSVs and figures, return the summary."""
    if collected is None:
        collected = collect(policies, quick, settings, seed, progress)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if not collected:
        return {"files": {}, "experiments": {}, "skipped": "no ORC(111) or ORC(110) policy among the runs"}

    results = {key: analyse(r) for key, (_, _, r) in collected.items()}
    counts = [[key, collected[key][1].name, f"{t:g}", *(int(res["counts"][g][c]) for g in GAITS),
               int(res["invalid"][c])] for key, res in results.items() for c, t in enumerate(res["times"])]
    files = {"counts_csv": write_csv(out / f"{FILE_STEM}_counts.csv",
                                     ["experiment", "policy", "time_s", *GAITS, "invalid_checkpoints"], counts)}

    rows = []
    for key, res in results.items():
        fell = collected[key][2].fell()
        final_phase = res["phase"].rpd[:, -1]
        for n in range(res["runs"]):
            vals = np.concatenate([res["initial_offsets"][n], res["initial_rpd"][n], res["final_rpd"][n],
                                   final_phase[n]])
            rows.append([key, n, *(f"{v:.5f}" for v in vals), res["initial_labels"][n], res["final_labels"][n],
                         int(fell[n])])
    cols = [f"{what}_{leg}" for what in ("offset0", "initial", "final_contact", "final_phase") for leg in RPD_NAMES]
    files["rpd_csv"] = write_csv(out / f"{FILE_STEM}_rpd.csv",
                                 ["experiment", "run", *cols, "initial_label", "final_label", "fell"], rows)

    with paper_style():
        fig = plot_scatter({k: (collected[k][0], results[k]) for k in results})
        files.update({f"scatter_{k}": v for k, v in save_figure(fig, out, f"{FILE_STEM}_rpd_scatter").items()})
        for key, res in results.items():
            fig = plot_distribution(collected[key][0], res)
            stem = f"{FILE_STEM}_distribution_{key}"
            files.update({f"distribution_{key}_{k}": v for k, v in save_figure(fig, out, stem).items()})

    summary = {}
    for key, res in results.items():
        exp, policy, _ = collected[key]
        summary[key] = {
            "policy": policy.name,
            "orc": exp.orc,
            "coupling": exp.coupling,
            **{k: res[k] for k in ("settling_time_s", "final_fractions", "contact_phase_label_agreement",
                                   "contact_phase_median_distance", "median_initial_final_distance", "falls",
                                   "runs")},
            "initial_fractions": {g: float(np.mean(res["initial_labels"] == g)) for g in GAITS},
            "checkpoints_s": [float(t) for t in res["times"]],
        }
    n_runs = next(iter(results.values()))["runs"]
    duration = collected[next(iter(collected))][2].num_steps * collected[next(iter(collected))][2].dt
    return {"files": files, "experiments": summary, "sizes": {"runs": n_runs, "duration_s": duration},
            "settings": settings.describe()}


# --- figures --------------------------------------------------------------------------------------


def ideal_gait_images() -> dict[str, np.ndarray]:
    """Every periodic image of each ideal RPD inside the cube [0, 2pi]^3 (0 also appears as 2pi)."""
    images = {}
    for name, rpd in gait.IDEAL_GAITS.items():
        options = [(v,) if v != 0.0 else (0.0, 2 * math.pi) for v in rpd]
        images[name] = np.array(list(itertools.product(*options)))
    return images


def plot_scatter(panels: dict):
    """3-D RPD scatter, one panel per experiment: initial (first two cycles) and final points."""
    fig = plt.figure(figsize=(WIDE_WIDTH, 2.7))
    images = ideal_gait_images()
    n = len(panels)
    for i, (key, (exp, res)) in enumerate(panels.items()):
        ax = fig.add_subplot(1, n, i + 1, projection="3d")
        for what, pts, style in (
            ("initial", res["initial_rpd"], dict(c="0.55", s=3, marker="o", alpha=0.5, lw=0)),
            ("final", res["final_rpd"], dict(c="tab:red", s=4, marker="^", alpha=0.8, lw=0)),
        ):
            ok = np.isfinite(pts).all(axis=1)
            ax.scatter(pts[ok, 0], pts[ok, 1], pts[ok, 2], label=f"{what} ({ok.sum()})", depthshade=False, **style)
        for name, pts in images.items():
            ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], marker="*", s=45, c=GAIT_COLORS[name], edgecolors="k",
                       linewidths=0.4, depthshade=False, label=name if i == 0 else None)
            label_at = pts[np.argmin(np.abs(pts - math.pi).sum(axis=1))]  # the most central image
            ax.text(*label_at, f" {name}", fontsize=5.5, color="k")
        for axis, leg in zip("xyz", RPD_NAMES):
            getattr(ax, f"set_{axis}ticks")([0, math.pi, 2 * math.pi], ["0", r"$\pi$", r"$2\pi$"])
            getattr(ax, f"set_{axis}lim")(0, 2 * math.pi)
            getattr(ax, f"set_{axis}label")(rf"RPD$_{{{leg}}}$ [rad]", labelpad=-8)
        ax.tick_params(pad=-3)
        ax.set_title(f"{exp.title}\nfinal: {_top_gaits(res['final_labels'])}", pad=-2)
        ax.view_init(elev=22, azim=-58)
        ax.set_box_aspect(None, zoom=0.82)
    handles, labels = fig.axes[0].get_legend_handles_labels()
    fig.legend(handles, [lab.split(" (")[0] for lab in labels], loc="lower center", ncols=6, frameon=False,
               markerscale=1.5)
    fig.subplots_adjust(left=0.0, right=0.97, bottom=0.1, top=0.9, wspace=0.12)
    return fig


def _top_gaits(labels, k: int = 3) -> str:
    labels = np.asarray(labels)
    if labels.size == 0:
        return "no runs"
    shares = sorted(((np.mean(labels == g), g) for g in GAITS), reverse=True)[:k]
    return ", ".join(f"{g} {100 * p:.0f}%" for p, g in shares if p > 0)


def plot_distribution(exp: Experiment, res: dict):
    """Stacked bars: share of runs in each gait at every checkpoint."""
    times, counts = res["times"], res["counts"]
    n = res["runs"]
    fig, ax = plt.subplots(figsize=(COLUMN_WIDTH, 2.3), layout="constrained")
    bottom = np.zeros(len(times))
    width = 0.7 * (times[1] - times[0]) if len(times) > 1 else 3.5
    segments = [(g, counts[g], g, None) for g in GAITS[:-1]]
    # Transition split into "no gait within distance 2" and invalid windows (< 2 cycles, or a leg never landed).
    segments += [("transition", counts["transition"] - res["invalid"], "transition", None),
                 ("transition", res["invalid"], "invalid window", "////")]
    for color_key, count, label, hatch in segments:
        share = 100.0 * np.asarray(count) / max(n, 1)
        ax.bar(times, share, width, bottom=bottom, color=GAIT_COLORS[color_key], label=label, edgecolor="white",
               lw=0.3, hatch=hatch)
        bottom += share
    ax.set_xticks(times)
    ax.set_xticklabels([f"{t:g}" for t in times])
    ax.set_xlabel("time [s]")
    ax.set_ylabel(f"runs [%] (of {n})")
    ax.set_ylim(0, 100)
    ax.set_title(f"{exp.title}: gait distribution over time")
    fig.legend(loc="outside lower center", ncols=3, frameon=False, handlelength=1.2, columnspacing=1.0)
    return fig


def main(argv=None) -> int:
    return cli_main("analysis.gait_emergence", __doc__, run, argv)


if __name__ == "__main__":
    sys.exit(main())
