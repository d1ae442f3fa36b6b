"""Step rate of the MuJoCo Warp backend (env-steps/s of `MujocoWarpBackend.step`) at several env counts.

One env-step is one control step of `--substeps` physics steps, with the per-substep
records, the divergence check and the copies of the results that the task gets. On CUDA
the control step is a replayed CUDA graph; on Warp's CPU device the kernels run one
after another from Python, which is for tests, not training.

    python bench/warp_throughput.py                          # CUDA: 4096 8192 16384 envs; CPU: 64 256 1024
    python bench/warp_throughput.py --num_envs 1024 4096 --steps 50
    python bench/warp_throughput.py --device cpu --num_envs 16 64
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from gym_envs.sim import make_backend

SCENE = "resources/robots/mini_cheetah/scene.xml"
FEET = ("RF_foot_force", "LF_foot_force", "RH_foot_force", "LH_foot_force")
GPU_ENVS = (4096, 8192, 16384)
CPU_ENVS = (64, 256, 1024)


def synchronize(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def measure(num_envs: int, device: torch.device, substeps: int, steps: int, rounds: int) -> dict:
    start = time.perf_counter()
    sim = make_backend(
        "warp", model_path=SCENE, num_envs=num_envs, foot_sensors=FEET, termination_sensors=("base_force",),
        device=device,
    )
    built = time.perf_counter() - start
    gen = torch.Generator().manual_seed(0)
    targets = [
        (sim.default_joint_pos.cpu() + 0.1 * torch.randn(num_envs, sim.num_joints, generator=gen)).to(device)
        for _ in range(steps)
    ]
    start = time.perf_counter()
    sim.step(targets[0], substeps)  # eager: compiles what is not cached yet
    sim.step(targets[1 % steps], substeps)  # CUDA: captures the graph
    synchronize(device)
    warmup = time.perf_counter() - start
    rates = []
    for _ in range(rounds):
        synchronize(device)
        start = time.perf_counter()
        for i in range(steps):
            sim.step(targets[i], substeps)
        synchronize(device)
        rates.append(steps * num_envs / (time.perf_counter() - start))
    return {"build_s": built, "warmup_s": warmup, "rate": statistics.median(rates), "rates": rates}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--num_envs", type=int, nargs="+", default=None)
    parser.add_argument("--device", default=None, help="torch/Warp device: cuda or cpu (default: cuda if available)")
    parser.add_argument("--substeps", type=int, default=5)
    parser.add_argument("--steps", type=int, default=None, help="control steps per timed round (cuda 100, cpu 5)")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    device = torch.device(args.device or ("cuda" if torch.cuda.is_available() else "cpu"))
    cuda = device.type == "cuda"
    env_counts = args.num_envs or (GPU_ENVS if cuda else CPU_ENVS)
    steps = args.steps or (100 if cuda else 5)
    torch.set_num_threads(1)

    name = torch.cuda.get_device_name(device) if cuda else "Warp CPU device"
    print(f"device {device} ({name}), substeps {args.substeps}, {args.rounds} rounds of {steps} control steps")
    print(f"{'envs':>7} {'build s':>8} {'warm-up s':>9} {'env-steps/s':>13} {'physics steps/s':>16}")
    for n in env_counts:
        r = measure(n, device, args.substeps, steps, args.rounds)
        print(
            f"{n:>7} {r['build_s']:>8.2f} {r['warmup_s']:>9.2f} {r['rate']:>13,.0f} {r['rate'] * args.substeps:>16,.0f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
