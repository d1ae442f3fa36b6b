"""Step rate of the simulation layer against raw `mujoco.batch` stepping of the same model.

Both run in one process on the same number of threads, in alternating rounds, so
machine noise hits them alike; the ratio of the medians is the figure to quote.

    python bench/sim_throughput.py                    # 4096 envs, 2 threads, 5 substeps
    python bench/sim_throughput.py --num_envs 512 --rounds 3
"""

from __future__ import annotations

import argparse
import statistics
import time

import mujoco
import mujoco.batch
import numpy as np
import torch

from gym_envs.sim import make_backend

SCENE = "resources/robots/mini_cheetah/scene.xml"
FEET = ("RF_foot_force", "LF_foot_force", "RH_foot_force", "LH_foot_force")


def timed(fn, steps: int) -> float:
    """env-steps per second of `steps` calls of fn."""
    start = time.perf_counter()
    for _ in range(steps):
        fn()
    return steps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--num_envs", type=int, default=4096)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--substeps", type=int, default=5)
    parser.add_argument("--steps", type=int, default=20, help="control steps per timed block")
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    torch.set_num_threads(1)
    n = args.num_envs

    layer = make_backend(
        "mujoco", model_path=SCENE, num_envs=n, foot_sensors=FEET, termination_sensors=("base_force",),
        num_threads=args.threads,
    )
    raw = mujoco.batch.Batch(layer.model, n, nthread=args.threads)
    raw.reset(keyframe=0)
    raw_ctrl = raw.bind("ctrl")
    rng = np.random.default_rng(0)
    home = layer.default_joint_pos.numpy().astype(np.float64)
    noise = [0.1 * rng.standard_normal((n, 12)) for _ in range(args.steps)]
    noise_t = [torch.from_numpy(x).float() for x in noise]
    home_t = layer.default_joint_pos

    def raw_step(i=[0]):
        raw_ctrl[:] = home + noise[i[0] % args.steps]
        raw.step(nstep=args.substeps)
        i[0] += 1

    def layer_step(i=[0]):
        layer.step(home_t + noise_t[i[0] % args.steps], args.substeps)
        i[0] += 1

    raw_step(), layer_step()  # warm up both
    raw_rates, layer_rates = [], []
    for _ in range(args.rounds):
        raw_rates.append(timed(raw_step, args.steps) * n)
        layer_rates.append(timed(layer_step, args.steps) * n)
    raw_rate, layer_rate = statistics.median(raw_rates), statistics.median(layer_rates)
    ratios = [a / b for a, b in zip(layer_rates, raw_rates)]
    print(f"envs {n}, threads {args.threads}, substeps {args.substeps}, {args.rounds} rounds of {args.steps} steps")
    print(f"raw mujoco.batch: {raw_rate:,.0f} env-steps/s ({raw_rate * args.substeps:,.0f} physics steps/s)")
    print(f"layer (records + torch): {layer_rate:,.0f} env-steps/s")
    print(f"layer/raw ratio: {statistics.median(ratios):.3f}")


if __name__ == "__main__":
    main()
