"""The recipe study's measurement of a training run's checkpoints: command envelope and oscillator obedience.

    python tools/evaluate_checkpoints.py logs/study/E15/<run> --every 100
    python tools/evaluate_checkpoints.py <run> --checkpoints 400 800

For each checkpoint (all checkpoints batched together, 16 robots per measurement by default):
  - the command envelope (analysis.envelope): every command of ENVELOPE at the trained coupling from
    random phases, 8 s after a 2 s start; how many commands are met (each axis within 0.25, no falls);
  - obedience (analysis.obedience): sigma = 0, oscillators started in trot / pace / bound / pronk at
    1 m/s, share walking that gait at 10 s; sigma = 1 from random phases, share regular at 10 s;
  - the verdict on both goals: every envelope command met, and Obedience.obeys (each started gait
    walked at half the command's speed or more by 80 % of the robots, 80 % regular at 10 s, no falls);
    then the first measured checkpoint meeting both, with the training minutes the run spent to reach it
    (issue 26's time to envelope and obedience, for a finished run; bench/time_to_obedience.py --envelope
    measures it while training).
One summary line per checkpoint on stdout, then every envelope line. --gait_speeds adds, per checkpoint
and speed, the started gaits at sigma = 0 under that forward command (walking: at half of it or more).
--confirm_seed chooses a checkpoint: those meeting both goals are measured again on a second evaluation
seed, and the last one meeting both there too is named (a checkpoint chosen by one draw of robots is
favoured by that draw; the second measurement is the unbiased one).
"""

from __future__ import annotations

import argparse
import sys

from analysis import envelope, obedience
from analysis.rollout import load_policy_run
from learning import runs


def evaluate(policies, robots: int, seed: int, num_threads: int) -> dict[str, bool]:
    """Measure the checkpoints, print a summary line each and the envelope's lines; {name: both goals met}."""
    env_results = envelope.measure(policies, robots=robots, num_threads=num_threads, seed=seed,
                                   **envelope.PROTOCOL_WINDOW)
    obeyed = obedience.measure(policies, robots=robots, settle_robots=robots, settle_duration_s=10.0,
                               num_threads=num_threads, seed=seed)
    met = {}
    for policy, ob in zip(policies, obeyed):
        rows = [r for r in env_results if r.policy == policy.name]
        missed = [f"{r.name} ({max(r.error):.2f}{', falls' if r.falls else ''})" for r in rows if not r.met]
        met[policy.name] = not missed and ob.obeys()
        verdict = f"envelope {'yes' if not missed else 'no'}, obedience {'yes' if ob.obeys() else 'no'}"
        print(f"{policy.name} | seed {seed} | goals: {verdict} | envelope met {len(rows) - len(missed)}/{len(rows)}"
              f"{' | missed: ' + '; '.join(missed) if missed else ''} | {ob.summary()}", flush=True)
    print("\n".join(envelope.summary_lines(env_results)))
    return met


def first_met_line(run_dir: str, met_iterations: list[int]) -> str:
    """The time to the first measured checkpoint that meets both goals, by the run's own training clock."""
    if not met_iterations:
        return "first checkpoint meeting both goals: none of those measured"
    first = met_iterations[0]
    seconds = runs.training_seconds(run_dir, until=first)
    clock = "no training time recorded" if seconds is None else (
        f"{seconds / 60:.1f} min of training by the run's own clock (its TensorBoard events: env stepping and PPO "
        "updates, on the machine and under the load it trained with)")
    return f"first checkpoint meeting both goals: it {first}, {clock}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir")
    parser.add_argument("--every", type=int, default=100, help="every this many iterations (default 100)")
    parser.add_argument("--checkpoints", type=int, nargs="*", default=None, help="these iterations instead")
    parser.add_argument("--robots", type=int, default=16)
    parser.add_argument("--num_threads", type=int, default=0)
    parser.add_argument("--seed", type=int, default=0,
                        help="evaluation seed (the robots' starting phases and draws)")
    parser.add_argument("--confirm_seed", type=int, default=None,
                        help="choose a checkpoint: re-measure those meeting both goals at this second evaluation "
                             "seed (draws they were not chosen by) and name the last one meeting both again")
    parser.add_argument("--gait_speeds", type=float, nargs="*", default=(), metavar="V",
                        help="also the started gaits at sigma = 0 under these forward commands [m/s]")
    args = parser.parse_args(argv)
    if args.confirm_seed is not None and args.confirm_seed == args.seed:
        parser.error(f"--confirm_seed {args.confirm_seed} is the evaluation seed: give another, e.g. {args.seed + 1}")

    available = runs.list_checkpoints(args.run_dir)
    wanted = args.checkpoints if args.checkpoints else [it for it in available if it > 0 and it % args.every == 0]
    missing = sorted(set(wanted) - set(available))
    if missing or not wanted:
        print(f"evaluate_checkpoints: error: no checkpoints {missing or wanted} in {args.run_dir} "
              f"(it has {available})", file=sys.stderr)
        return 1
    policies = [load_policy_run(args.run_dir, it, name=f"it {it}") for it in wanted]
    met = evaluate(policies, args.robots, args.seed, args.num_threads)
    print(first_met_line(args.run_dir, [it for it in wanted if met[f"it {it}"]]))
    for speed in args.gait_speeds:
        at_speed = obedience.measure(policies, robots=args.robots, settle_robots=0, num_threads=args.num_threads,
                                     command=speed, progress=False, seed=args.seed)
        for policy, ob in zip(policies, at_speed):
            print(f"{policy.name} | command {speed:g} m/s | {ob.summary()}")
    if args.confirm_seed is not None:
        candidates = [p for p in policies if met[p.name]]
        confirmed = evaluate(candidates, args.robots, args.confirm_seed, args.num_threads) if candidates else {}
        chosen = [p.name for p in candidates if confirmed[p.name]]
        print(f"chosen: {chosen[-1] if chosen else 'none'} (both goals at evaluation seed {args.seed}: "
              f"{', '.join(p.name for p in candidates) or 'none'}; again at seed {args.confirm_seed}: "
              f"{', '.join(chosen) or 'none'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
