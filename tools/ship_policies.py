"""Copy finished sweep runs into resources/policies/ and write their manifest with measured metrics.

    python tools/ship_policies.py --runs logs/sweep --machine "2-core CPU (dev machine)"

For each ORC_<xyz>/seed<k> run of the sweep (the first seed found per configuration unless
--seed is given): env.yaml, train.yaml and the newest checkpoint go to resources/policies/ORC_<xyz>/;
the policy is then checked at 1 m/s on 16 robots with random oscillator phases, over 20 s after a 2 s start
(analysis.locomotion), and resources/policies/manifest.csv records configuration, command, commit,
seed, iterations, wall time, the machine that trained it and the measured metrics.
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import subprocess
import sys

import yaml

from analysis.locomotion import check_locomotion
from gym_envs.orc import PAPER_CONFIGURATIONS
from learning import runs

FIELDS = ("orc", "command_mps", "commit", "seed", "iterations", "wall_time_s", "machine", "profile",
          "tracking_error_mps", "mean_velocity_mps", "falls", "robots", "gaits")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", required=True, help="a sweep folder (ORC_<xyz>/seed<k>/ runs)")
    parser.add_argument("--out", default=runs.POLICY_ROOT)
    parser.add_argument("--seed", type=int, default=None)
    parser.add_argument("--machine", required=True, help="what trained the runs, for the manifest")
    parser.add_argument("--commit", default=None, help="the commit that trained the runs (default: HEAD)")
    parser.add_argument("--num_threads", type=int, default=2)
    args = parser.parse_args(argv)
    commit = args.commit or subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                                           text=True).stdout.strip()
    rows = []
    for orc in PAPER_CONFIGURATIONS:
        folder = os.path.join(args.runs, f"ORC_{orc}")
        seeds = sorted(os.listdir(folder)) if os.path.isdir(folder) else []
        if args.seed is not None:
            seeds = [s for s in seeds if s == f"seed{args.seed}"]
        if not seeds:
            print(f"ORC {orc}: no run in {folder}; skipped")
            continue
        run_dir = os.path.join(folder, seeds[0])
        iteration = max(runs.list_checkpoints(run_dir))
        target = os.path.join(args.out, f"ORC_{orc}")
        os.makedirs(target, exist_ok=True)
        for old in os.listdir(target):
            os.remove(os.path.join(target, old))
        for name in (runs.ENV_YAML, runs.TRAIN_YAML, os.path.basename(runs.checkpoint_path(run_dir, iteration))):
            shutil.copy2(os.path.join(run_dir, name), os.path.join(target, name))
        loaded = runs.load_policy(target)
        check = check_locomotion(loaded.policy, loaded.env_cfg, command=1.0, warmup_s=2.0, measure_s=20.0,
                                 num_envs=16, num_threads=args.num_threads)
        print(f"ORC {orc} ({run_dir}, iteration {iteration}): {check.summary()}", flush=True)
        with open(os.path.join(run_dir, "sweep_status.yaml")) as f:
            status = yaml.safe_load(f)
        rows.append({
            "orc": orc, "command_mps": 1.0, "commit": commit, "seed": loaded.train_cfg.seed, "iterations": iteration,
            "wall_time_s": status.get("wall_time_s", ""), "machine": args.machine, "profile": loaded.train_cfg.profile,
            "tracking_error_mps": round(check.tracking_error, 3), "mean_velocity_mps": round(check.mean_velocity, 3),
            "falls": check.falls, "robots": check.num_envs,
            "gaits": "; ".join(f"{g} {share:.2f}" for g, share in check.gaits.items()),
        })
    with open(os.path.join(args.out, "manifest.csv"), "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=FIELDS)
        writer.writeheader()
        writer.writerows(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
