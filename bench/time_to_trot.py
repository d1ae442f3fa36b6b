"""Wall-clock minutes until mini_cheetah_osc ORC-111 trots at 1 m/s, trained with a profile on this machine.

Trains with `--profile` (default cpu_fast) and, every `--eval_every` iterations, pauses the clock and
evaluates the current deterministic policy: 16 robots, random oscillator phases, command 1 m/s,
no noise, pushes or randomisation (the analysis evaluation setting), 12 s of which the last 10 s
count. The policy has trotted when, over those 10 s:
  - the tracking error is below 0.15 m/s: per robot |mean forward velocity - 1 m/s|, averaged;
  - no robot fell;
  - at least 75 % of robots walk a regular gait, trot or pronk by the paper's classifier
    (relative phase differences of the footfalls at the 5 s and 10 s checkpoints, analysis.gait).
The clock counts training only (env stepping and PPO updates), not the evaluations.

    python bench/time_to_trot.py                         # prints 'minutes to trot: <x>' at the end
    python bench/time_to_trot.py --max_minutes 30 --log_root logs/bench   # keep the run folder
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import torch

import train
from analysis.locomotion import check_locomotion
from gym_envs.config import save_yaml
from learning import runs
from learning.runs import DeterministicActor

MAX_ERROR = 0.15  # [m/s]
MIN_REGULAR_SHARE = 0.75


def trots(check) -> bool:
    return check.tracking_error < MAX_ERROR and check.falls == 0 and check.regular_share >= MIN_REGULAR_SHARE


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profile", default="cpu_fast")
    parser.add_argument("--eval_every", type=int, default=10, help="PPO iterations between evaluations")
    parser.add_argument("--max_minutes", type=float, default=30.0, help="training time before giving up")
    parser.add_argument("--num_threads", type=int, default=2)
    parser.add_argument("--eval_envs", type=int, default=16)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--log_root", default=None, help="keep the run here (default: a temporary folder)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args(argv)

    torch.set_num_threads(args.num_threads)
    log_root = args.log_root or tempfile.mkdtemp(prefix="time_to_trot_")
    train_argv = ["--task", "mini_cheetah_osc", "--orc", "111", "--profile", args.profile, "--seed", str(args.seed),
                  "--num_threads", str(args.num_threads), "--max_iterations", "1000000"]
    for override in args.overrides:
        train_argv += ["--set", override]
    setup = train.prepare(train.build_parser().parse_args(train_argv))
    runner, env_cfg, train_cfg = setup.runner, setup.env_cfg, setup.train_cfg
    run_dir = runs.create_run_dir(log_root, "time_to_trot", f"{args.profile}_seed{args.seed}")
    save_yaml(env_cfg, os.path.join(run_dir, runs.ENV_YAML))
    save_yaml(train_cfg, os.path.join(run_dir, runs.TRAIN_YAML))
    runner.attach_run_dir(run_dir, progress_prefix="[time_to_trot] ")
    steps_per_iteration = env_cfg.env.num_envs * train_cfg.num_steps_per_env
    print(f"profile {args.profile}: {env_cfg.env.num_envs} envs x {train_cfg.num_steps_per_env} steps, "
          f"{runner.describe()}; run folder {run_dir}", flush=True)

    clock, reached = 0.0, None
    while clock < args.max_minutes * 60:
        start = time.perf_counter()
        first = runner.current_learning_iteration == 0
        runner.train(runner.current_learning_iteration + args.eval_every, init_at_random_ep_len=first)
        clock += time.perf_counter() - start
        it = runner.current_learning_iteration
        check = check_locomotion(DeterministicActor(runner.alg.get_policy()), env_cfg, command=1.0,
                                 num_envs=args.eval_envs, num_threads=args.num_threads)
        print(f"eval | it {it} | {clock / 60:6.2f} min | {it * steps_per_iteration / 1e6:6.2f} M steps | "
              f"{check.summary()}", flush=True)
        if trots(check):
            reached = clock / 60
            break
    runner.save(runs.checkpoint_path(run_dir, runner.current_learning_iteration))
    if reached is None:
        print(f"minutes to trot: not reached within {args.max_minutes:g}")
        return 1
    print(f"minutes to trot: {reached:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
