"""How often robots fall at one envelope command, on more robots than the protocol's 16.

    python tools/fall_rate.py resources/policies/ORC_110/seed0 resources/policies/ORC_110/seed1 --robots 256
    python tools/fall_rate.py <run or policy folder> ... --command "forward 3" --seed 1

Each policy folder's newest checkpoint gets `--robots` robots from random phases at its trained coupling and the
command (a name of analysis.envelope.ENVELOPE, default standing), in the envelope's window (8 s after a 2 s
start), all policies in shared batches (so the draws depend on which policies are measured together and on
--seed). One line per policy: robots fallen in the window, of how many, and that share. A miss of the envelope
by one fall in 16 robots is a draw or a rate; this tells which.
"""

from __future__ import annotations

import argparse
import sys

from analysis import envelope
from analysis.rollout import load_policy_run


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policies", nargs="+", help="run or shipped-policy folders")
    parser.add_argument("--command", default="stand", choices=list(envelope.ENVELOPE), metavar="NAME",
                        help=f"an envelope command: {', '.join(envelope.ENVELOPE)} (default: stand)")
    parser.add_argument("--robots", type=int, default=256)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--num_threads", type=int, default=2)
    args = parser.parse_args(argv)
    runs = [load_policy_run(folder) for folder in args.policies]
    results = envelope.measure(runs, commands={args.command: envelope.ENVELOPE[args.command]}, robots=args.robots,
                               seed=args.seed, num_threads=args.num_threads, progress=False,
                               **envelope.PROTOCOL_WINDOW)
    for folder, result in zip(args.policies, results):
        print(f"{folder} | {args.command} | fell {result.falls} of {result.robots} "
              f"({100 * result.falls / result.robots:.1f} %) | max error {max(result.error):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
