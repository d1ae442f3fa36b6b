"""Training curves of a sweep's runs: reward, tracking error and episode length against env steps.

    python tools/plot_training_curves.py --runs logs/sweep --out docs/training_curves.png

Reads each run's tensorboard events (ORC_<xyz>/seed<k>/, every events file of a resumed run, later files winning
where iterations overlap) and draws one line per configuration.
"""

from __future__ import annotations

import argparse
import glob
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator  # noqa: E402

from gym_envs.orc import PAPER_CONFIGURATIONS  # noqa: E402
from learning import runs  # noqa: E402

PANELS = (
    ("Train/mean_reward", "mean episode return"),
    ("Episode/tracking_error", "tracking error [m/s]"),
    ("Train/mean_episode_length", "episode length [steps]"),
)


def curves(run_dir: str) -> dict[str, tuple[list[float], list[float]]]:
    """tag -> (env steps, values) over every event file of the run."""
    _, env_cfg, train_cfg = runs.load_run_configs(run_dir)
    steps_per_iteration = env_cfg.env.num_envs * train_cfg.num_steps_per_env
    out: dict[str, dict[int, float]] = {tag: {} for tag, _ in PANELS}
    # A resumed run restarts every robot's episode at a random point of its length, so for one episode length
    # its episode statistics count only episodes cut short: a dip of the logging, not of the policy, left out.
    restart_iterations = math.ceil(env_cfg.env.episode_length_s * env_cfg.control.frequency_hz
                                   / train_cfg.num_steps_per_env)
    for path in sorted(glob.glob(os.path.join(run_dir, "events.out.tfevents.*"))):
        acc = EventAccumulator(path)
        acc.Reload()
        for tag in out:
            if tag in acc.Tags()["scalars"]:
                events = acc.Scalars(tag)
                if events and events[0].step > 0:
                    events = [e for e in events if e.step >= events[0].step + restart_iterations]
                out[tag].update({e.step: e.value for e in events})
    return {tag: ([(s + 1) * steps_per_iteration for s in sorted(v)], [v[s] for s in sorted(v)])
            for tag, v in out.items()}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", required=True)
    parser.add_argument("--out", default="docs/training_curves.png")
    args = parser.parse_args(argv)
    fig, axes = plt.subplots(1, len(PANELS), figsize=(10, 3.0), constrained_layout=True)
    for orc in PAPER_CONFIGURATIONS:
        for run_dir in sorted(glob.glob(os.path.join(args.runs, f"ORC_{orc}", "seed*"))):
            data = curves(run_dir)
            for ax, (tag, _) in zip(axes, PANELS):
                steps, values = data[tag]
                ax.plot([s / 1e6 for s in steps], values, lw=1.0, label=f"ORC {orc}")
    for ax, (_, label) in zip(axes, PANELS):
        ax.set_xlabel("env steps [millions]")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    handles, labels = axes[0].get_legend_handles_labels()
    unique = dict(zip(labels, handles))
    fig.legend(unique.values(), unique.keys(), loc="outside lower center", ncol=7, fontsize=8, frameon=False)
    fig.savefig(args.out, dpi=150)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
