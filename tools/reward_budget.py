"""What a policy is paid for at each command: its reward, term by term, where it goes.

    python tools/reward_budget.py resources/policies/ORC_011/seed0 resources/policies/ORC_111/seed0
    python tools/reward_budget.py <run or policy folder> ... --command "forward 3" --command 2.5,0,0 --robots 16

Each policy folder's newest checkpoint gets `--robots` robots from random phases at its trained coupling, per
command (a name of analysis.envelope.ENVELOPE or "v_x,v_y,yaw_rate"; default: the envelope's forward commands),
in the envelope's window (8 s after a 2 s start). One line per policy and command: the tracked velocities, the
robots fallen, and every reward term the policy's env computes, weighted, as its mean per second over the window
and the robots that stayed up (the same units as training's Episode_Reward logs), then their sum. Where a policy
tracks a command badly, this shows which term pays it for that.
"""

from __future__ import annotations

import argparse
import sys

from analysis import envelope
from analysis.rollout import load_policy_run

DEFAULT_COMMANDS = ("forward 0.5", "forward 1", "forward 2", "forward 3")


def parse_command(text: str) -> tuple[str, tuple[float, float, float]]:
    """An envelope command name, or three comma-separated numbers (v_x, v_y, yaw rate)."""
    if text in envelope.ENVELOPE:
        return text, envelope.ENVELOPE[text]
    try:
        values = tuple(float(x) for x in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3:
        names = ", ".join(map(repr, envelope.ENVELOPE))
        raise argparse.ArgumentTypeError(f"{text!r} is neither an envelope command ({names}) nor 'v_x,v_y,yaw_rate'")
    return text, values


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policies", nargs="+", help="run or shipped-policy folders")
    parser.add_argument("--command", dest="commands", action="append", type=parse_command, metavar="COMMAND",
                        help="an envelope command name or 'v_x,v_y,yaw_rate'; repeat for more "
                             f"(default: {', '.join(DEFAULT_COMMANDS)})")
    parser.add_argument("--robots", type=int, default=16)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--num_threads", type=int, default=2)
    args = parser.parse_args(argv)
    commands = dict(args.commands or [parse_command(name) for name in DEFAULT_COMMANDS])
    runs = [load_policy_run(folder) for folder in args.policies]
    results = envelope.measure(runs, commands=commands, robots=args.robots, seed=args.seed,
                               num_threads=args.num_threads, progress=False, reward_terms=True,
                               **envelope.PROTOCOL_WINDOW)
    per_policy = len(commands)
    for k, result in enumerate(results):
        folder = args.policies[k // per_policy]
        tracked = ", ".join(f"{x:+.2f}" for x in result.tracked)
        terms = " ".join(f"{name} {rate:+.3f}" for name, rate in result.rewards.items())
        print(f"{folder} | {result.name} {result.command} -> ({tracked}) | fell {result.falls} of {result.robots} | "
              f"{terms} | sum {sum(result.rewards.values()):+.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
