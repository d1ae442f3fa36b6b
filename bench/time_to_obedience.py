"""Wall-clock minutes until mini_cheetah_osc ORC-111 walks, and until it obeys its oscillators.

Trains ORC-111 with `--profile` (default cpu_oscillators, the forward-only recipe, whose 600 iterations
fit the default 10-iteration evaluation steps; the task's CPU recipe cpu_envelope wants
`--profile cpu_envelope --envelope --eval_every 100 --max_minutes 90`) and, every `--eval_every` iterations, pauses the
clock and evaluates the current deterministic policy in the analysis evaluation setting (no noise,
pushes or randomisation), at a 1 m/s command:
  - walking (analysis.locomotion, 16 robots, random phases, 12 s of which the last 10 s count):
    tracking error below 0.15 m/s (per robot |mean forward velocity - 1|, averaged) and no falls;
  - obedience (analysis.obedience, 16 robots per gait): with coupling sigma = 0 and the oscillators
    started in trot, pace, bound and pronk, at least 80 % of robots walk that gait at 10 s (contact-based
    gaits, analysis.gait), no falls. Each evaluation also says whether the stricter goal holds: every
    started gait at 1.0 +- 0.15 m/s, and with sigma = 1 from random phases >= 80 % in a regular gait at 10 s.
  - with --envelope, the command envelope too (analysis.envelope: every command of ENVELOPE, 16 robots
    from random phases at the trained coupling, 8 s after a 2 s start; met when each axis is within
    0.25 and no robot falls), and 'minutes to envelope and obedience' is the first evaluation where
    every command is met and the robots obey.
A pronk reached from random phases counts for walking, never for obedience. The clock counts
training only (env stepping and PPO updates), not the evaluations. The run stops once it both walks
and obeys (and, with --envelope, meets the envelope at one evaluation), or after --max_minutes.
For a run already trained, `python tools/evaluate_checkpoints.py <run>` names the first saved checkpoint
meeting envelope and obedience with the training minutes its TensorBoard events record.

    python bench/time_to_obedience.py              # prints 'minutes to walking' and 'minutes to obedience'
    python bench/time_to_obedience.py --max_minutes 30 --log_root logs/bench   # keep the run folder
    python bench/time_to_obedience.py --profile cpu_envelope --envelope --eval_every 100 --max_minutes 90   # issue 26's goal
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time

import torch

from analysis import envelope, obedience
from analysis.locomotion import check_locomotion
from analysis.rollout import PolicyRun
from learning import launch, runs
from learning.runs import DeterministicActor

MAX_ERROR = 0.15  # [m/s]
MIN_SHARE = 0.8  # of robots walking the started gait (sigma = 0) or a regular one (sigma = 1)


def walks(check) -> bool:
    return check.tracking_error < MAX_ERROR and check.falls == 0


def obeys(result: obedience.Obedience) -> bool:
    return all(s.obeyed >= MIN_SHARE and s.falls == 0 for s in result.started.values())


def meets_speed_and_coupling(result: obedience.Obedience) -> bool:
    """The stricter goal: each started gait also at 1.0 +- 0.15 m/s, and >= 80 % regular at sigma = 1 by 10 s."""
    speeds_ok = all(abs(s.velocity - 1.0) <= MAX_ERROR for s in result.started.values())
    return speeds_ok and result.settling.regular_at_10s >= MIN_SHARE and result.settling.falls == 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profile", default="cpu_oscillators")
    parser.add_argument("--eval_every", type=int, default=10, help="PPO iterations between evaluations")
    parser.add_argument("--max_minutes", type=float, default=30.0, help="training time before giving up")
    parser.add_argument("--num_threads", type=int, default=2)
    parser.add_argument("--eval_envs", type=int, default=16)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--log_root", default=None, help="keep the run here (default: a temporary folder)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--envelope", action="store_true", help="also measure the command envelope at each evaluation")
    args = parser.parse_args(argv)

    torch.set_num_threads(args.num_threads)
    log_root = args.log_root or tempfile.mkdtemp(prefix="time_to_obedience_")
    plan = launch.resolve(launch.RunRequest(
        task="mini_cheetah_osc", orc="111", profile=args.profile, seed=args.seed, num_threads=args.num_threads,
        max_iterations=1_000_000, log_root=log_root, experiment_name="time_to_obedience",
        run_name=f"{args.profile}_seed{args.seed}", overrides=args.overrides,
    ))
    runner, run_dir, lock = launch.start_run(plan)  # noqa: F841 (the lock is held to the end)
    env_cfg, train_cfg = plan.env_cfg, plan.train_cfg
    steps_per_iteration = env_cfg.env.num_envs * train_cfg.num_steps_per_env
    print(f"profile {args.profile}: {env_cfg.env.num_envs} envs x {train_cfg.num_steps_per_env} steps, "
          f"{runner.describe()}; run folder {run_dir}", flush=True)

    clock, walking, obedient, everywhere = 0.0, None, None, None
    while clock < args.max_minutes * 60 and (obedient is None or walking is None
                                              or (args.envelope and everywhere is None)):
        start = time.perf_counter()
        first = runner.current_learning_iteration == 0
        runner.learn(args.eval_every, init_at_random_ep_len=first)
        clock += time.perf_counter() - start
        it = runner.current_learning_iteration
        actor = DeterministicActor(runner.alg.get_policy())
        check = check_locomotion(actor, env_cfg, command=1.0, num_envs=args.eval_envs, num_threads=args.num_threads)
        head = f"eval | it {it} | {clock / 60:6.2f} min | {it * steps_per_iteration / 1e6:6.2f} M steps"
        print(f"{head} | {check.summary()}", flush=True)
        if walking is None and walks(check):
            walking = (clock / 60, it, check)
        (result,) = obedience.measure([PolicyRun(f"it {it}", env_cfg, actor)], robots=args.eval_envs,
                                      settle_robots=args.eval_envs, settle_duration_s=10.0,
                                      num_threads=args.num_threads, progress=False)
        print(f"{head} | {result.summary()} | speeds and sigma = 1 goal: "
              f"{'met' if meets_speed_and_coupling(result) else 'not met'}", flush=True)
        if obedient is None and obeys(result):
            obedient = (clock / 60, it, result)
        if args.envelope:
            commands = envelope.measure([PolicyRun(f"it {it}", env_cfg, actor)], robots=args.eval_envs,
                                        num_threads=args.num_threads, progress=False,
                                        **envelope.PROTOCOL_WINDOW)
            missed = [c.name for c in commands if not c.met]
            print(f"{head} | envelope met {len(commands) - len(missed)}/{len(commands)}"
                  + (f", missed: {', '.join(missed)}" if missed else ""), flush=True)
            if everywhere is None and not missed and obeys(result):
                everywhere = (clock / 60, it, result)
    runner.save(runs.checkpoint_path(run_dir, runner.current_learning_iteration))
    goals = [("walking", walking), ("obedience", obedient)]
    if args.envelope:
        goals.append(("envelope and obedience", everywhere))
    for name, reached in goals:
        if reached is None:
            print(f"minutes to {name}: not reached within {args.max_minutes:g}")
        else:
            minutes, it, measured = reached
            print(f"minutes to {name}: {minutes:.2f} (iteration {it}; {measured.summary()})")
    return 0 if obedient is not None and (everywhere is not None or not args.envelope) else 1


if __name__ == "__main__":
    sys.exit(main())
