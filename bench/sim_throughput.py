"""Step rates of the physics layer and of the full task, against raw physics stepping.

--sim mujoco (default): three contenders in one process, on the same threads, in alternating
rounds so machine noise hits them alike; the median of the per-round ratios is the figure:
- raw: `mujoco.batch.Batch.step` of the same model, controls written from numpy;
- layer: the backend's step (per-substep records, torch conversion, divergence checks);
- env: the whole `mini_cheetah_osc` control step (oscillators, rewards, resets, observations).

--sim warp: the MuJoCo Warp backend's step and the full `mini_cheetah_osc` step on it, at
several env counts (CUDA when there is one; Warp's CPU device is only for tests).

    python bench/sim_throughput.py                          # 4096 envs, 2 threads, 5 substeps
    python bench/sim_throughput.py --num_envs 512 --rounds 3
    python bench/sim_throughput.py --sim warp               # 4096 8192 16384 envs on CUDA
"""

from __future__ import annotations

import argparse
import statistics
import time

import mujoco.batch
import torch

from gym_envs import env_cfg_class, make_env
from gym_envs.sim import make_backend

SCENE = "resources/robots/mini_cheetah/scene.xml"
FEET = ("RF_foot_force", "LF_foot_force", "RH_foot_force", "LH_foot_force")


def steps_per_second(fn, steps: int, device: torch.device) -> float:
    """Calls of fn per second over `steps` calls (synchronising CUDA before reading the clock)."""
    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)
    sync()
    start = time.perf_counter()
    for i in range(steps):
        fn(i)
    sync()
    return steps / (time.perf_counter() - start)


def build_env(num_envs: int, backend: str, threads: int, device: torch.device):
    cfg = env_cfg_class("mini_cheetah_osc")()
    cfg.env.num_envs, cfg.env.device = num_envs, str(device)
    cfg.sim.backend, cfg.sim.num_threads = backend, threads
    return make_env("mini_cheetah_osc", cfg)


def random_actions(num_envs: int, steps: int, device: torch.device) -> list[torch.Tensor]:
    gen = torch.Generator().manual_seed(0)
    return [torch.randn(num_envs, 12, generator=gen).to(device) for _ in range(steps)]


def bench_mujoco(args) -> None:
    n, device = args.num_envs[0], torch.device("cpu")
    layer = make_backend(
        "mujoco", model_path=SCENE, num_envs=n, foot_sensors=FEET, termination_sensors=("base_force",),
        num_threads=args.num_threads,
    )
    raw = mujoco.batch.Batch(layer.model, n, nthread=args.num_threads)
    raw.reset(keyframe=0)
    raw_ctrl = raw.bind("ctrl")
    home = layer.default_joint_pos
    targets = [home + 0.1 * a for a in random_actions(n, args.steps, device)]
    targets_np = [t.double().numpy() for t in targets]
    env = build_env(n, "mujoco", args.num_threads, device)
    actions = random_actions(n, args.steps, device)

    def raw_step(i):
        raw_ctrl[:] = targets_np[i]
        raw.step(nstep=args.substeps)

    contenders = {
        "raw": raw_step,
        "layer": lambda i: layer.step(targets[i], args.substeps),
        "env": lambda i: env.step(actions[i]),
    }
    rates = {name: [] for name in contenders}
    for fn in contenders.values():
        fn(0)  # warm up
    for _ in range(args.rounds):
        for name, fn in contenders.items():
            rates[name].append(steps_per_second(fn, args.steps, device) * n)
    median = {name: statistics.median(r) for name, r in rates.items()}

    def ratio(name):
        return statistics.median(a / b for a, b in zip(rates[name], rates["raw"]))

    print(f"envs {n}, threads {args.num_threads}, substeps {args.substeps}, {args.rounds} rounds of {args.steps} steps")
    print(f"raw mujoco.batch: {median['raw']:,.0f} env-steps/s ({median['raw'] * args.substeps:,.0f} physics steps/s)")
    print(f"layer (records + torch): {median['layer']:,.0f} env-steps/s")
    print(f"env (mini_cheetah_osc step): {median['env']:,.0f} env-steps/s")
    print(f"layer/raw ratio: {ratio('layer'):.3f}")
    print(f"env/raw ratio: {ratio('env'):.3f}")


def bench_warp(args) -> None:
    device = torch.device(args.device or ("cuda" if torch.cuda.is_available() else "cpu"))
    name = torch.cuda.get_device_name(device) if device.type == "cuda" else "Warp CPU device (for tests only)"
    print(f"device {device} ({name}), substeps {args.substeps}, {args.rounds} rounds of {args.steps} steps")
    print(f"{'envs':>7} {'layer env-steps/s':>18} {'env env-steps/s':>16}")
    for n in args.num_envs:
        env = build_env(n, "warp", 0, device)
        targets = [env.default_joint_pos + 0.1 * a for a in random_actions(n, args.steps, device)]
        actions = random_actions(n, args.steps, device)
        layer_fn = lambda i: env.sim.step(targets[i], args.substeps)  # noqa: E731
        env_fn = lambda i: env.step(actions[i])  # noqa: E731
        for fn in (layer_fn, env_fn):
            fn(0), fn(1)  # compile, then capture the CUDA graph
        layer = statistics.median(steps_per_second(layer_fn, args.steps, device) * n for _ in range(args.rounds))
        full = statistics.median(steps_per_second(env_fn, args.steps, device) * n for _ in range(args.rounds))
        print(f"{n:>7} {layer:>18,.0f} {full:>16,.0f}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sim", choices=("mujoco", "warp"), default="mujoco")
    parser.add_argument("--num_envs", type=int, nargs="+", default=None,
                        help="mujoco: one count (4096); warp: several (4096 8192 16384 on CUDA, 64 256 on CPU)")
    parser.add_argument("--num_threads", type=int, default=2, help="mujoco backend threads")
    parser.add_argument("--device", default=None, help="warp: cuda or cpu (default: cuda when available)")
    parser.add_argument("--substeps", type=int, default=5)
    parser.add_argument("--steps", type=int, default=20, help="control steps per timed round")
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    torch.set_num_threads(1)
    if args.sim == "mujoco":
        args.num_envs = args.num_envs or [4096]
        bench_mujoco(args)
    else:
        cuda = (args.device or ("cuda" if torch.cuda.is_available() else "cpu")).startswith("cuda")
        args.num_envs = args.num_envs or ([4096, 8192, 16384] if cuda else [64, 256])
        bench_warp(args)


if __name__ == "__main__":
    main()
