"""Balanced leg use (paper fig. "legvariance", analysis protocol §2).

Per policy, robots with i.i.d. random oscillator phases run for 10 s at a 1 m/s forward command
from a standing start; for each robot and leg the normalised GRF is averaged over the whole episode
(start-up transient included). Values of all policies of one ORC configuration are pooled, and each
(configuration, leg) gets one violin. Perfectly balanced use gives 0.25 for every leg.

Robots that fall are kept (the paper does not say) and counted; after a fall a robot stands with a
zero command, which pulls its mean towards static loading.

Usage: python -m analysis.balanced_legs --runs DIR --out DIR [--quick]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from analysis.plotting import (
    COLUMN_WIDTH,
    LEG_COLORS,
    LEG_NAMES,
    config_color,
    paper_style,
    save_figure,
    sort_configs,
    write_csv,
)
from analysis.rollout import EvalSettings, Job, cli_main, run_jobs
from analysis.stats import policy_interval

import matplotlib.pyplot as plt  # noqa: E402  (after analysis.plotting selected the Agg backend)

BALANCED = 0.25  # each leg carries a quarter of the body weight on average
NEAR_ZERO = 0.05  # a leg averaging less than this is "held up or dragged" (2- or 3-legged gait)
PROTOCOL = {"robots_per_policy": 50, "duration_s": 10.0}
QUICK = {"robots_per_policy": 10, "duration_s": 5.0}
COMMAND = 1.0  # [m/s] forward
FILE_STEM = "balanced_legs"


def mean_grf_per_leg(grf) -> np.ndarray:
    """Per-robot, per-leg average of the normalised GRF over the episode: (N, T, 4) -> (N, 4)."""
    grf = np.asarray(grf, float)
    if grf.ndim != 3 or grf.shape[-1] != 4:
        raise ValueError(f"expected GRF of shape (N, T, 4), got {grf.shape}")
    return grf.mean(axis=1)


def leg_statistics(mean_grf) -> dict:
    """Distribution summary of pooled per-robot leg means (N, 4)."""
    g = np.asarray(mean_grf, float)
    q25, median, q75 = np.percentile(g, [25, 50, 75], axis=0)
    return {
        "n": int(g.shape[0]),
        "median": median,
        "iqr": q75 - q25,
        "mean": g.mean(axis=0),
        "std": g.std(axis=0),
        **{name: statistic(g) if len(g) else float("nan") for name, statistic in POLICY_STATISTICS.items()},
    }


def frac_leg_near_zero(g: np.ndarray) -> float:
    """The share of robots with at least one leg carrying (almost) nothing."""
    return float(np.mean((g < NEAR_ZERO).any(axis=1)))


def mean_max_deviation(g: np.ndarray) -> float:
    """Mean over robots of the largest deviation of a leg from the balanced 0.25."""
    return float(np.mean(np.abs(g - BALANCED).max(axis=1)))


POLICY_STATISTICS = {"frac_leg_near_zero": frac_leg_near_zero, "mean_max_deviation": mean_max_deviation}


def run(policies, out_dir, quick: bool = False, settings: EvalSettings = EvalSettings(), seed: int = 0,
        progress: bool = True) -> dict:
    """Roll out every policy, write the CSVs and the violin figure, return a summary per configuration."""
    sizes = QUICK if quick else PROTOCOL
    robots, duration = sizes["robots_per_policy"], sizes["duration_s"]
    if not policies:
        raise ValueError("balanced_legs needs at least one policy")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)

    steps = int(round(duration * policies[0].env_cfg.control.frequency_hz))
    jobs = [Job(p, robots) for p in policies]
    rollouts = run_jobs(jobs, steps, settings, command=(COMMAND, 0.0, 0.0), record=("grf", "terminated"),
                        seed=seed, progress=progress, label="balanced legs")

    rows, identical = [], {}
    for policy, r in zip(policies, rollouts):
        g = mean_grf_per_leg(r.data["grf"])
        identical[policy.orc] = identical.get(policy.orc, True) and r.robots_alike()
        fell = r.fell()
        for i in range(r.num_envs):
            rows.append({"config": policy.orc, "run": policy.name, "robot": i, "fell": bool(fell[i]),
                         **{leg: float(g[i, j]) for j, leg in enumerate(LEG_NAMES)}})

    fields = ["config", "run", "robot", "fell", *LEG_NAMES]
    per_robot_csv = write_csv(out / f"{FILE_STEM}.csv", fields, ([r[k] for k in fields] for r in rows))

    configs = sort_configs({r["config"] for r in rows})
    pooled = {c: np.array([[r[leg] for leg in LEG_NAMES] for r in rows if r["config"] == c]) for c in configs}
    falls = {c: sum(r["fell"] for r in rows if r["config"] == c) for c in configs}
    n_policies = {c: len({r["run"] for r in rows if r["config"] == c}) for c in configs}
    stats = {c: leg_statistics(pooled[c]) for c in configs}
    # The same two statistics per policy, and their 95 % interval over policies (robots resampled within them).
    per_policy = {c: [np.array([[r[leg] for leg in LEG_NAMES] for r in rows if r["run"] == name])
                      for name in dict.fromkeys(r["run"] for r in rows if r["config"] == c)] for c in configs}
    for c in configs:
        stats[c]["policy_max_deviation"] = [mean_max_deviation(g) for g in per_policy[c]]
        for name, statistic in POLICY_STATISTICS.items():
            stats[c][f"{name}_interval"] = policy_interval(per_policy[c], statistic)
        stats[c]["leg_mean_interval"] = [policy_interval(per_policy[c], lambda g, j=j: g[:, j].mean())
                                         for j in range(len(LEG_NAMES))]

    spreads = ("median", "iqr")
    summary_csv = write_csv(
        out / f"{FILE_STEM}_summary.csv",
        ["config", "policies", "robots", "falls", "frac_leg_near_zero", "mean_max_deviation",
         *(f"{what}_{leg}" for leg in LEG_NAMES for what in spreads)],
        ([c, n_policies[c], s["n"], falls[c], f"{s['frac_leg_near_zero']:.4f}", f"{s['mean_max_deviation']:.4f}",
          *(f"{s[what][j]:.4f}" for j in range(len(LEG_NAMES)) for what in spreads)] for c, s in stats.items()))

    with paper_style():
        fig = plot(pooled, {c: stats[c]["leg_mean_interval"] for c in configs}, n_policies)
    figs = save_figure(fig, out, FILE_STEM)
    return {
        "files": {"csv": per_robot_csv, "summary_csv": summary_csv, **figs},
        "sizes": {"robots_per_policy": robots, "duration_s": duration, "command_mps": COMMAND},
        "settings": settings.describe(),
        "configs": {c: {**stats[c], "falls": falls[c], "policies": n_policies[c], "identical_robots": identical[c]}
                    for c in configs},
    }


def plot(pooled: dict[str, np.ndarray], leg_intervals: dict[str, list], policies: dict[str, int]):
    """One violin per (configuration, leg) over the pooled robots; configurations along x, legs side by
    side within a group; on each violin the mean over policies with its 95 % interval (leg_intervals:
    per configuration, (estimate, low, high) per leg)."""
    configs = list(pooled)
    fig, ax = plt.subplots(figsize=(COLUMN_WIDTH, 2.4), constrained_layout=True)
    slot, group = 0.2, 1.0
    top = 0.6
    for ci, c in enumerate(configs):
        data = pooled[c]
        for j in range(4):
            x = ci * group + (j - 1.5) * slot
            values = data[:, j]
            top = max(top, float(values.max()) * 1.05 if len(values) else top)
            _violin(ax, x, values, LEG_COLORS[j], width=slot * 0.95)
            estimate, low, high = leg_intervals[c][j]
            ax.errorbar(x, estimate, yerr=[[estimate - low], [high - estimate]], fmt="o", ms=1.6, color="black",
                        elinewidth=0.7, capsize=1.2, zorder=3)
    ax.axhline(BALANCED, color="0.3", lw=0.6, ls="--", zorder=0)
    ax.text(len(configs) - 0.5, BALANCED, " 0.25", va="center", ha="left", fontsize=6, color="0.3",
            clip_on=False)
    ax.set_xticks(np.arange(len(configs)) * group)
    ax.set_xticklabels([f"ORC\n{c}" for c in configs])
    for tick, c in zip(ax.get_xticklabels(), configs):
        tick.set_color(config_color(c) if c in ("110", "111") else "black")
    ax.set_xlim(-0.5, len(configs) - 0.5)
    ax.set_ylim(0.0, min(top, 1.0))
    ax.set_ylabel("mean normalised GRF per robot [BW]")
    ax.set_xlabel("configuration")
    handles = [plt.Rectangle((0, 0), 1, 1, fc=col, alpha=0.6, ec=col) for col in LEG_COLORS]
    ax.legend(handles, LEG_NAMES, ncols=4, loc="upper left", frameon=False, handlelength=1.0, columnspacing=0.8)
    n = {len(v) for v in pooled.values()}
    k = sorted(set(policies.values()))
    ax.set_title(f"Leg use at 1 m/s, {'/'.join(map(str, sorted(n)))} robots per configuration\n"
                 f"(dots: mean over {'/'.join(map(str, k))} policies, 95 % interval)")
    return fig


def _violin(ax, x, values, color, width):
    values = np.asarray(values, float)
    if len(values) >= 2 and np.ptp(values) > 1e-6:
        parts = ax.violinplot(values, positions=[x], widths=width, showextrema=False, bw_method=0.3)
        for body in parts["bodies"]:
            body.set_facecolor(color)
            body.set_edgecolor(color)
            body.set_alpha(0.6)
            body.set_linewidth(0.4)
    elif len(values):
        ax.plot([x - width / 2, x + width / 2], [values[0], values[0]], color=color, lw=1.2)
    if len(values):
        q25, med, q75 = np.percentile(values, [25, 50, 75])
        ax.plot([x, x], [q25, q75], color="k", lw=0.8, solid_capstyle="butt")
        ax.plot(x, med, "o", ms=1.8, mfc="white", mec="k", mew=0.4)


def main(argv=None) -> int:
    return cli_main("analysis.balanced_legs", __doc__, run, argv)


if __name__ == "__main__":
    sys.exit(main())
