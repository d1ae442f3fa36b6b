"""Disturbance rejection: failure rate after a planar velocity impulse (paper Table I, protocol §6).

Per policy and impulse magnitude A, a "push ball" of robots: slot k (of 50) and direction j (of 36),
robot n = 36 k + j. One control step with zero command (the released scripts' env creation), then a
3 m/s forward command; 5 s of settling, then a 10 s test window. Just before test step 100 + k,
the robots of slot k get A (cos theta_j, sin theta_j) added to their world-frame trunk velocity, so
the 50 slots sample the gait phase every 0.01 s over 0.5 s. A ball with fewer slots (--push_slots,
--quick) spreads them over the same 0.5 s, so it still samples a whole gait cycle, more coarsely. Directions as in the released code,
theta_j = 2 pi j / 35 for j = 0..35 (0 and 360 degrees both, about 10.3 degrees apart);
`direction_mode="even"` gives 10-degree spacing as the paper's text says.

The command is the protocol's 3 m/s only where every policy was trained on it: a policy trained on
slower commands (cpu_oscillators: v_x in {1, 2} m/s) would be pushed outside its task, and its
failures would measure that. So by default robots are pushed at the highest forward command all
policies were trained on, capped at 3 m/s (`push_command`); --push_command sets it.

A robot fails if it terminated (trunk contact) at any step from the command up to the
test sample the released analysis reads (index 998 of 1000, the second to last): the same event
as its logged command being reset to 0 there. Falls before the pushes count as well (reported
separately, with their share: the protocol wants them under 1 %). Per policy: failure rate in %; per configuration: mean +- population std over its
policies, one decimal, lowest mean in each row bold (ties all bold), as in Table I.

Magnitudes are simulated side by side in one batch, each on fresh robots (the released sweep ran
them one after another on the same robots; fresh starts are the cleaner choice the protocol
allows).

Usage: python -m analysis.disturbance --runs DIR --out DIR [--quick] [--push_slots N] [--push_command V]
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from analysis.plotting import (COLUMN_WIDTH, config_color, markdown_table, mean_std_text, paper_style, save_figure,
                               sort_configs, write_csv)
from analysis.rollout import DEFAULT_MAX_BATCH, EvalSettings, Job, cli_main, pack_batches, run_jobs

import matplotlib.pyplot as plt  # noqa: E402  (after analysis.plotting selected the Agg backend)

MAGNITUDES = (1.5, 2.0, 2.5, 3.0, 3.5)  # m/s, the rows of Table I
QUICK_MAGNITUDES = (1.5, 2.5, 3.5)
FILE_STEM = "disturbance"


@dataclass(frozen=True)
class PushBall:
    slots: int = 50
    directions: int = 36
    direction_mode: str = "release"  # 'release': 2 pi j / (D - 1), j = 0..D-1; 'even': 2 pi j / D
    command: float = 3.0  # m/s forward, the protocol's
    settle_s: float = 5.0
    test_s: float = 10.0
    push_at_s: float = 1.0  # first slot's push, into the test window
    push_span_s: float = 0.5  # the slots spread over this span, at least one control step apart
    fail_sample: int = -2  # test sample whose state decides (negative: from the end)

    @property
    def robots(self) -> int:
        return self.slots * self.directions

    def angles(self) -> np.ndarray:
        j = np.arange(self.directions)
        if self.direction_mode == "release":
            return 2 * math.pi * j / max(self.directions - 1, 1)
        if self.direction_mode == "even":
            return 2 * math.pi * j / self.directions
        raise ValueError(f"direction_mode {self.direction_mode!r} is unknown; use 'release' or 'even'")

    def slot_interval_steps(self, dt: float) -> int:
        """Control steps between consecutive slots."""
        return max(1, int(round(self.push_span_s / dt)) // self.slots)

    def timeline(self, dt: float) -> dict:
        """Control-step indices. Step 0 has a zero command; the command is set before step 1."""
        settle, test = int(round(self.settle_s / dt)), int(round(self.test_s / dt))
        push0 = 1 + settle + int(round(self.push_at_s / dt))
        fail = self.fail_sample if self.fail_sample >= 0 else test + self.fail_sample
        if not 0 <= fail < test:
            raise ValueError(f"fail_sample {self.fail_sample} is outside the {test}-step test window")
        last_push = push0 + (self.slots - 1) * self.slot_interval_steps(dt)
        if last_push > settle + test:
            raise ValueError("the pushes do not fit in the test window")
        return {
            "total": 1 + settle + test,
            "command_step": 1,
            "test_start": 1 + settle,
            "first_push": push0,
            "last_push": last_push,
            # Window of the failure test in *recorded* samples (recording starts at step 1).
            "fail_window_end": settle + fail + 1,
            "pre_push_end": push0 - 1,
        }

    def pushes(self, magnitude: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """(push_step (N,), push_delta (N, 2)) for robot n = directions * slot + direction."""
        n = np.arange(self.robots)
        slot, direction = n // self.directions, n % self.directions
        step = self.timeline(dt)["first_push"] + slot * self.slot_interval_steps(dt)
        theta = self.angles()[direction]
        return step, magnitude * np.stack([np.cos(theta), np.sin(theta)], axis=1)


PROTOCOL_BALL = PushBall()
QUICK_BALL = PushBall(slots=4, directions=8, direction_mode="even", settle_s=2.0, test_s=2.5, push_at_s=0.5)


def default_ball(quick: bool, slots: int | None = None) -> PushBall:
    """The protocol's (or --quick's) ball, with `slots` push slots per direction when given."""
    ball = QUICK_BALL if quick else PROTOCOL_BALL
    return ball if slots is None else replace(ball, slots=slots)


def trained_forward_speed(env_cfg) -> float:
    """The highest forward command [m/s] a policy was trained on: the top choice of a choice-based
    draw (its noise aside), else the top of the uniform range."""
    commands = env_cfg.commands
    return float(max(commands.lin_vel_x_choices) if commands.lin_vel_x_choices else commands.lin_vel_x[1])


def push_command(policies, requested: float | None = None, protocol: float = PROTOCOL_BALL.command) -> float:
    """The forward command of the push ball: `requested`, else the protocol's, lowered to the highest
    command every policy was trained on."""
    if requested is not None:
        return float(requested)
    trained = min(trained_forward_speed(p.env_cfg) for p in policies)
    if trained <= 0:
        raise ValueError(f"a policy was never trained to walk forward (top v_x command {trained:g} m/s); "
                         "give the push ball's command with --push_command")
    return min(protocol, trained)


# --- scoring --------------------------------------------------------------------------------------


def failed(terminated, window_end: int) -> np.ndarray:
    """(N,) robots with a termination in recorded samples [0, window_end) of (N, T) flags."""
    terminated = np.asarray(terminated, bool)
    if terminated.ndim != 2:
        raise ValueError(f"expected terminated flags of shape (N, T), got {terminated.shape}")
    return terminated[:, :window_end].any(axis=1)


def failure_rate(fails) -> float:
    """Failure rate in % of the robots."""
    fails = np.asarray(fails, bool)
    return 100.0 * float(fails.mean()) if fails.size else float("nan")


def mean_std(values) -> tuple[float, float]:
    """Mean and population standard deviation (divide by N, as the released analysis)."""
    v = np.asarray(values, float)
    if v.size == 0:
        return float("nan"), float("nan")
    return float(v.mean()), float(v.std(ddof=0))


def format_failure_table(rates: dict, magnitudes=None, configs=None) -> str:
    """Markdown table of mean +- std failure rate [%] per impulse (rows) and configuration (columns).

    rates[config][magnitude] is the list of per-policy failure rates. The lowest mean of a row is bold,
    every tied one too; means are compared unrounded, as the paper's table does (its 0.0 ± 0.1 cells,
    a few failures, are not bold beside exact zeros). A missing cell is '–'.
    """
    configs = list(configs) if configs is not None else sort_configs(rates)
    if magnitudes is None:
        magnitudes = sorted({m for c in configs for m in rates.get(c, {})})
    rows = []
    for m in magnitudes:
        cells = {c: mean_std(rates[c][m]) for c in configs if len(rates.get(c, {}).get(m, ()))}
        best = min((mean for mean, _ in cells.values() if math.isfinite(mean)), default=math.nan)
        rows.append([f"{m:.1f}"] + [mean_std_text(*cells[c], bold=abs(cells[c][0] - best) <= 1e-9)
                                    if c in cells else "–" for c in configs])
    return markdown_table(["Impulse [m/s]", *configs], rows)


# --- experiment -----------------------------------------------------------------------------------


def run(policies, out_dir, quick: bool = False, settings: EvalSettings = EvalSettings(), seed: int = 0,
        push_slots: int | None = None, command: float | None = None, progress: bool = True) -> dict:
    """Push-ball every policy at every magnitude; write CSVs, Table I (markdown) and figures.

    `push_slots` resizes the default ball to that many slots per direction: fewer robots, the same
    directions, magnitudes and push span. `command` [m/s] overrides `push_command`'s choice.
    """
    if not policies:
        raise ValueError("disturbance needs at least one policy")
    magnitudes = QUICK_MAGNITUDES if quick else MAGNITUDES
    ball = replace(default_ball(quick, push_slots), command=push_command(policies, command))
    command_source = ("requested" if command is not None else
                      "protocol" if ball.command == PROTOCOL_BALL.command else "trained range")
    dt = 1.0 / policies[0].env_cfg.control.frequency_hz
    tl = ball.timeline(dt)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)

    jobs = []
    for p in policies:
        for m in magnitudes:
            step, delta = ball.pushes(m, dt)
            jobs.append(Job(p, ball.robots, step, delta, tag=m))
    # Simulate chunk by chunk and keep only reductions, so memory stays that of one batch.
    chunks = pack_batches(jobs, lambda job: job.num_envs, DEFAULT_MAX_BATCH)

    records = []
    for c, chunk in enumerate(chunks):
        rollouts = run_jobs(chunk, tl["total"], settings, command=(ball.command, 0.0, 0.0),
                            command_step=tl["command_step"], record=("terminated", "base_lin_vel"), record_from=1,
                            seed=seed + 1000 * c, progress=progress,
                            label=f"push ball, part {c + 1}/{len(chunks)}" if len(chunks) > 1 else "push ball")
        for job, r in zip(chunk, rollouts):
            term = r.data["terminated"]
            fails = failed(term, tl["fail_window_end"])
            records.append({
                "config": job.run.orc,
                "run": job.run.name,
                "magnitude": job.tag,
                "robots": job.num_envs,
                "failures": int(fails.sum()),
                "failure_rate_pct": failure_rate(fails),
                "falls_before_push": int(failed(term, tl["pre_push_end"]).sum()),
                "vx_test": r.data["base_lin_vel"][:, tl["test_start"] - 1:, 0].mean(axis=0),
            })

    per_policy_csv = write_csv(
        out / f"{FILE_STEM}_per_policy.csv",
        ["config", "run", "impulse_mps", "robots", "failures", "failure_rate_pct", "falls_before_push"],
        ([r["config"], r["run"], r["magnitude"], r["robots"], r["failures"], f"{r['failure_rate_pct']:.4f}",
          r["falls_before_push"]] for r in records))

    configs = sort_configs({r["config"] for r in records})
    rates = {c: {m: [r["failure_rate_pct"] for r in records if r["config"] == c and r["magnitude"] == m]
                 for m in magnitudes} for c in configs}
    table_md = format_failure_table(rates, magnitudes, configs)
    table_path = out / f"{FILE_STEM}_table.md"
    table_path.write_text(f"Failure rate [%] after a velocity impulse, mean ± std over policies\n\n{table_md}\n")

    stats = {c: {m: (*mean_std(rates[c][m]), len(rates[c][m])) for m in magnitudes} for c in configs}
    summary_csv = write_csv(out / f"{FILE_STEM}_summary.csv",
                            ["config", "impulse_mps", "policies", "mean_pct", "std_pct"],
                            ([c, m, n, f"{mean:.4f}", f"{std:.4f}"] for c in configs
                             for m, (mean, std, n) in stats[c].items()))

    with paper_style():
        figs = save_figure(plot_failure_rates(stats, magnitudes, ball.command), out, f"{FILE_STEM}_failure_rate")
        vel = {c: np.mean([r["vx_test"] for r in records if r["config"] == c and r["magnitude"] == max(magnitudes)],
                          axis=0) for c in configs}
        t0 = tl["test_start"]
        push_window = ((tl["first_push"] - t0) * dt, (tl["last_push"] - t0 + 1) * dt)
        vfigs = save_figure(plot_velocity(vel, dt, push_window, max(magnitudes), ball.command), out,
                            f"{FILE_STEM}_velocity")

    return {
        "files": {"per_policy_csv": per_policy_csv, "summary_csv": summary_csv, "table_md": table_path,
                  **{f"failure_rate_{k}": v for k, v in figs.items()},
                  **{f"velocity_{k}": v for k, v in vfigs.items()}},
        "table_markdown": table_md,
        "rates": rates,
        "stats": stats,
        "falls_before_push": {c: sum(r["falls_before_push"] for r in records if r["config"] == c) for c in configs},
        "falls_before_push_pct": {c: 100.0 * sum(r["falls_before_push"] for r in records if r["config"] == c)
                                  / sum(r["robots"] for r in records if r["config"] == c) for c in configs},
        "sizes": {"robots_per_policy_and_impulse": ball.robots, "slots": ball.slots, "directions": ball.directions,
                  "direction_mode": ball.direction_mode, "settle_s": ball.settle_s, "test_s": ball.test_s,
                  "magnitudes": list(magnitudes), "command_mps": ball.command, "protocol_command_mps": PROTOCOL_BALL.command,
                  "command_source": command_source,
                  "push_span_s": ball.push_span_s, "slot_interval_s": ball.slot_interval_steps(dt) * dt},
        "settings": settings.describe(),
    }


def plot_failure_rates(stats: dict, magnitudes, command: float):
    fig, ax = plt.subplots(figsize=(COLUMN_WIDTH, 2.7), layout="constrained")
    configs = list(stats)
    spread = 0.03 * (max(magnitudes) - min(magnitudes) + 0.5)
    for i, c in enumerate(configs):
        x = np.asarray(magnitudes) + (i - (len(configs) - 1) / 2) * spread / max(len(configs) - 1, 1) * 2
        mean = np.array([stats[c][m][0] for m in magnitudes])
        std = np.array([stats[c][m][1] for m in magnitudes])
        strong = c in ("111", "110")
        ax.errorbar(x, mean, yerr=std, color=config_color(c), marker="o", ms=2.5 if not strong else 3.2,
                    lw=1.4 if c == "111" else 0.9, capsize=1.5, elinewidth=0.6, label=f"ORC {c}")
    ax.set_xlabel("impulse magnitude [m/s]")
    ax.set_ylabel("failure rate [%]")
    ax.set_xticks(list(magnitudes))
    ax.set_ylim(bottom=0)
    fig.legend(ncols=4, frameon=False, loc="outside lower center", handlelength=1.5, columnspacing=1.0)
    ax.set_title(f"Failure rate after a planar velocity impulse\n({command:g} m/s command; mean ± std over policies)")
    return fig


def plot_velocity(vel: dict, dt: float, push_window, magnitude: float, command: float):
    fig, ax = plt.subplots(figsize=(COLUMN_WIDTH, 2.6), layout="constrained")
    for c, v in vel.items():
        t = (np.arange(len(v)) + 1) * dt
        ax.plot(t, v, color=config_color(c), lw=1.2 if c == "111" else 0.8, label=f"ORC {c}")
    ax.axvspan(*push_window, color="0.85", zorder=0, label="pushes")
    ax.axhline(command, color="0.4", lw=0.5, ls="--")
    ax.set_xlabel("time in test window [s]")
    ax.set_ylabel(r"mean forward velocity $v_x$ [m/s]")
    ax.set_title(f"Mean forward velocity around {magnitude:g} m/s impulses\n(all robots and policies; fallen robots "
                 f"stand at 0 m/s)")
    fig.legend(ncols=4, frameon=False, loc="outside lower center", handlelength=1.5, columnspacing=1.0)
    return fig


def main(argv=None) -> int:
    return cli_main("analysis.disturbance", __doc__, run, argv, pushes=True)


if __name__ == "__main__":
    sys.exit(main())
