"""Step rates of the simulation layer and of the full task against raw `mujoco.batch` stepping.

Three contenders, one process, the same threads, in alternating rounds so machine
noise hits them alike; the median of the per-round ratios is the figure to quote:
- raw: `mujoco.batch.Batch.step` of the same model, controls written from numpy;
- layer: the backend's step (per-substep records, torch conversion, divergence checks);
- env: the whole `mini_cheetah_osc` control step (oscillators, rewards, resets, observations).

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

from gym_envs import env_cfg_class, make_env
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

    cfg = env_cfg_class("mini_cheetah_osc")()
    cfg.env.num_envs, cfg.sim.num_threads = n, args.threads
    env = make_env("mini_cheetah_osc", cfg)
    actions = [torch.randn(n, env.num_actions, generator=torch.Generator().manual_seed(i)) for i in range(args.steps)]

    def env_step(i=[0]):
        env.step(actions[i[0] % args.steps])
        i[0] += 1

    contenders = {"raw": raw_step, "layer": layer_step, "env": env_step}
    rates = {name: [] for name in contenders}
    for fn in contenders.values():
        fn()  # warm up
    for _ in range(args.rounds):
        for name, fn in contenders.items():
            rates[name].append(timed(fn, args.steps) * n)
    median = {name: statistics.median(r) for name, r in rates.items()}

    def ratio(name):
        return statistics.median(a / b for a, b in zip(rates[name], rates["raw"]))

    print(f"envs {n}, threads {args.threads}, substeps {args.substeps}, {args.rounds} rounds of {args.steps} steps")
    print(f"raw mujoco.batch: {median['raw']:,.0f} env-steps/s ({median['raw'] * args.substeps:,.0f} physics steps/s)")
    print(f"layer (records + torch): {median['layer']:,.0f} env-steps/s")
    print(f"env (mini_cheetah_osc step): {median['env']:,.0f} env-steps/s")
    print(f"layer/raw ratio: {ratio('layer'):.3f}")
    print(f"env/raw ratio: {ratio('env'):.3f}")


if __name__ == "__main__":
    main()
