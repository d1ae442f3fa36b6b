"""Copy finished sweep runs into resources/policies/ and write their manifest with measured metrics.

    python tools/ship_policies.py --runs logs/sweep --machine "2-core CPU (dev machine)"
    python tools/ship_policies.py --runs logs/sweep --seed 2 --machine ...   # only the seed-2 runs
    python tools/ship_policies.py --remeasure          # measure the shipped policies again, keep provenance

Every ORC_<xyz>/seed<k> run of the sweep (only seed k with --seed) is shipped to
resources/policies/ORC_<xyz>/seed<k>/: env.yaml, train.yaml and the newest checkpoint (k is the seed its
train.yaml records). Policies shipped earlier stay, so the seeds of a sweep that spans sessions can be
shipped as they land; a run shipped again replaces its folder and its manifest row.
Each shipped policy is then measured at 1 m/s in the evaluation setting:
  - walking: 16 robots with random oscillator phases, 20 s after a 2 s start (analysis.locomotion):
    tracking error, falls, and the gait mix at the end both from foot contacts and from the
    oscillator phases, with their agreement;
  - obedience: sigma = 0, oscillators started in trot / pace / bound / pronk, 16 robots each, share
    walking that gait at 10 s; sigma = 1 from random phases, 16 robots, share in a regular gait at
    10 s, and each leg's share of the GRF there (RF/LF/RH/LH) (analysis.obedience);
  - the command envelope: every command of analysis.envelope.ENVELOPE, 16 robots from random phases at the
    trained coupling, 8 s after a 2 s start: commands met, the largest per-axis error, falls.
resources/policies/manifest.csv records configuration, command, commit, seed, iterations, wall time (a
sweep's own record, else the training time the run's TensorBoard events add up to, through the run it was
resumed from), the machine that trained it and the measured metrics. A run resumed from a shipped policy's
checkpoint (say, to train it longer) carries that policy's row on: its wall time is added, and its commit and
machine are kept beside this run's.
"""

from __future__ import annotations

import argparse
import csv
import filecmp
import os
import shutil
import subprocess
import sys

import yaml

from analysis import envelope, obedience
from analysis.gait import mix_text
from analysis.locomotion import check_locomotion
from analysis.plotting import write_csv
from analysis.rollout import load_policy_run
from gym_envs.orc import PAPER_CONFIGURATIONS
from learning import runs

PROVENANCE = ("orc", "command_mps", "commit", "seed", "iterations", "wall_time_s", "machine", "profile")
METRICS = ("tracking_error_mps", "mean_velocity_mps", "falls", "robots", "gaits_contacts", "gaits_oscillators",
           "gait_label_agreement", "robots_alike", *(f"obeys_{g}" for g in obedience.STARTED_GAITS),
           "sigma1_regular_at_10s", "sigma1_grf_shares", "envelope_met", "envelope_max_error", "envelope_falls")
FIELDS = PROVENANCE + METRICS
ROBOTS = 16


def measure(policy_dir: str, num_threads: int) -> dict:
    """The manifest's metric columns for one shipped policy folder."""
    run = load_policy_run(policy_dir)
    check = check_locomotion(run.policy, run.env_cfg, command=1.0, warmup_s=2.0, measure_s=20.0, num_envs=ROBOTS,
                             num_threads=num_threads)
    (obeyed,) = obedience.measure([run], robots=ROBOTS, settle_robots=ROBOTS, settle_duration_s=10.0,
                                  num_threads=num_threads, progress=False)
    commands = envelope.measure([run], robots=ROBOTS, num_threads=num_threads, progress=False,
                                **envelope.PROTOCOL_WINDOW)
    print(f"ORC {run.orc} ({policy_dir}): {check.summary()}\n    {obeyed.summary()}\n    "
          + "\n    ".join(envelope.summary_lines(commands)), flush=True)
    return {
        "tracking_error_mps": round(check.tracking_error, 3), "mean_velocity_mps": round(check.mean_velocity, 3),
        "falls": check.falls, "robots": check.num_envs,
        "gaits_contacts": mix_text(check.gaits, check.identical),
        "gaits_oscillators": mix_text(check.oscillator_gaits),
        "gait_label_agreement": round(check.agreement, 3),
        "robots_alike": int(check.identical),
        **{f"obeys_{g}": round(s.obeyed, 3) for g, s in obeyed.started.items()},
        "sigma1_regular_at_10s": round(obeyed.settling.regular_at_10s, 3),
        "sigma1_grf_shares": "/".join(f"{x:.2f}" for x in obeyed.settling.leg_shares),
        "envelope_met": f"{sum(c.met for c in commands)}/{len(commands)}",
        "envelope_max_error": round(max(max(c.error) for c in commands), 3),
        "envelope_falls": sum(c.falls for c in commands),
    }


def ship(args) -> list[dict]:
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    rows = []
    for orc in PAPER_CONFIGURATIONS:
        folder = os.path.join(args.runs, f"ORC_{orc}")
        names = sorted(os.listdir(folder)) if os.path.isdir(folder) else []
        if args.seed is not None:
            names = [n for n in names if n == f"seed{args.seed}"]
        run_dirs = [os.path.join(folder, n) for n in names if runs.is_run_dir(os.path.join(folder, n))
                    and runs.list_checkpoints(os.path.join(folder, n))]
        if not run_dirs:
            print(f"ORC {orc}: no finished run in {folder}; skipped")
        for run_dir in run_dirs:
            rows.append(ship_run(run_dir, orc, args, head))
    return rows


def continued_row(run_dir: str, orc: str, seed: int, out: str) -> dict | None:
    """The manifest row of the shipped policy `run_dir` was resumed from (its checkpoint, byte for byte), if any."""
    resumed_from = runs.load_run_configs(run_dir)[2].resumed_from
    if not resumed_from or not os.path.isfile(resumed_from):
        return None
    iteration = runs.checkpoint_iteration(resumed_from)
    shipped = runs.checkpoint_path(runs.shipped_policy_dir(orc, seed, out), iteration)
    if not os.path.isfile(shipped) or not filecmp.cmp(resumed_from, shipped, shallow=False):
        return None
    return next((row for row in read_manifest(out) if (row["orc"], int(row["seed"]), int(row["iterations"]))
                 == (orc, seed, iteration)), None)


def ship_run(run_dir: str, orc: str, args, head: str) -> dict:
    iteration = max(runs.list_checkpoints(run_dir))
    seed = runs.load_run_configs(run_dir)[2].seed
    commit = args.commit or runs.trained_commit(run_dir) or head
    machine = args.machine
    status_path = os.path.join(run_dir, "sweep_status.yaml")  # a run trained by train.py has none
    status = {}
    if os.path.isfile(status_path):
        with open(status_path) as f:
            status = yaml.safe_load(f) or {}
    wall_time = status.get("wall_time_s")
    if wall_time is None:
        seconds = runs.training_seconds(run_dir)
        wall_time = "" if seconds is None else round(seconds, 1)
    earlier = continued_row(run_dir, orc, seed, args.out)
    if earlier is not None:  # a shipped policy trained on: its provenance carries over
        own = runs.training_seconds(run_dir, resumed_chain=False)
        wall_time = ("" if own is None or not earlier["wall_time_s"]
                     else round(float(earlier["wall_time_s"]) + own, 1))
        commit = f"{earlier['commit']} then {commit}"
        machine = (f"iterations 1-{earlier['iterations']}: {earlier['machine']}; "
                   f"{int(earlier['iterations']) + 1}-{iteration}: {machine}")
    target = runs.shipped_policy_dir(orc, seed, args.out)
    os.makedirs(target, exist_ok=True)
    for old in os.listdir(target):
        os.remove(os.path.join(target, old))
    for name in (runs.ENV_YAML, runs.TRAIN_YAML, os.path.basename(runs.checkpoint_path(run_dir, iteration))):
        shutil.copy2(os.path.join(run_dir, name), os.path.join(target, name))
    loaded = runs.load_policy(target)
    return {
        "orc": orc, "command_mps": 1.0, "commit": commit, "seed": seed, "iterations": iteration,
        "wall_time_s": wall_time, "machine": machine, "profile": loaded.train_cfg.profile,
        **measure(target, args.num_threads),
    }


def remeasure(args) -> list[dict]:
    return [{**{k: row[k] for k in PROVENANCE},
             **measure(runs.shipped_policy_dir(row["orc"], int(row["seed"]), args.out), args.num_threads)}
            for row in read_manifest(args.out)]


def read_manifest(out: str) -> list[dict]:
    path = os.path.join(out, "manifest.csv")
    if not os.path.isfile(path):
        return []
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def merged(old: list[dict], new: list[dict]) -> list[dict]:
    """The manifest's rows: the new ones, and the old ones no new row replaces; by configuration, then seed."""
    key = lambda row: (str(row["orc"]), int(row["seed"]))  # noqa: E731
    rows = {key(row): row for row in old}
    rows.update({key(row): row for row in new})
    order = {orc: i for i, orc in enumerate(PAPER_CONFIGURATIONS)}
    return [rows[k] for k in sorted(rows, key=lambda k: (order.get(k[0], len(order)), k[1]))]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", help="a sweep folder (ORC_<xyz>/seed<k>/ runs) to ship")
    parser.add_argument("--remeasure", action="store_true",
                        help="measure the policies already in --out again; provenance columns are kept")
    parser.add_argument("--out", default=runs.POLICY_ROOT)
    parser.add_argument("--seed", type=int, default=None)
    parser.add_argument("--machine", help="what trained the runs, for the manifest (needed with --runs)")
    parser.add_argument("--commit", default=None, help="the commit that trained the runs (default: the one each run "
                        "recorded in its git/ folder, else HEAD)")
    parser.add_argument("--num_threads", type=int, default=2)
    args = parser.parse_args(argv)
    if bool(args.runs) == args.remeasure:
        parser.error("give either --runs DIR (with --machine) or --remeasure")
    if args.runs and not args.machine:
        parser.error("--runs needs --machine (what trained the runs)")
    rows = remeasure(args) if args.remeasure else merged(read_manifest(args.out), ship(args))
    # Rows shipped before a column existed leave it empty until --remeasure.
    write_csv(os.path.join(args.out, "manifest.csv"), FIELDS, ([row.get(k, "") for k in FIELDS] for row in rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
