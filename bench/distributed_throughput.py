"""Rollout env-steps/s of 1 process x N threads against N processes x 1 thread, at the same total robots.

Which layout to give train.py on a CPU, of three:
  - `python train.py --num_threads N`: N MuJoCo threads and N torch threads in one process;
  - `OMP_NUM_THREADS=1 python train.py --set sim.num_threads=N`: the same with one torch thread
    (torch's OpenMP workers spin after each parallel op, taking cores from MuJoCo's threads);
  - `torchrun --nproc_per_node=N train.py --num_threads 1`, with 1/N of the robots each.
Every process runs what
a rollout step of training runs: the actor MLP ([256, 256, 128]) on the observations, the full
`mini_cheetah_osc` step, and rsl-rl's observation normalisers, whose statistics the N processes
all-reduce over gloo each step, as under torchrun (so they advance in lockstep). The rounds alternate
between the layouts so that machine noise hits both; the figure is the median of the per-round
ratios. The PPO update is not timed here.

    python bench/distributed_throughput.py                       # 4096 robots, 2 processes vs 1 x 2 threads
    python bench/distributed_throughput.py --num_envs 1024 --rounds 8 --processes 4
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import socket
import statistics
import time

import torch
import torch.distributed as dist
from rsl_rl.modules import EmpiricalNormalization

from gym_envs import env_cfg_class, make_env


def worker(conn, rank: int, world: int, port: int, num_envs: int, threads: int, torch_threads: int,
           seed: int) -> None:
    """One process of a layout: builds its env, then times `steps` rollout steps per request."""
    torch.set_num_threads(torch_threads)
    if world > 1:
        dist.init_process_group("gloo", init_method=f"tcp://127.0.0.1:{port}", rank=rank, world_size=world)
    cfg = env_cfg_class("mini_cheetah_osc")()
    cfg.env.num_envs, cfg.env.seed, cfg.sim.num_threads = num_envs, seed + rank, threads
    env = make_env("mini_cheetah_osc", cfg)
    obs = env.get_observations()
    normalisers = {group: EmpiricalNormalization(obs[group].shape[1]) for group in ("actor", "critic")}
    actor = torch.nn.Sequential(
        torch.nn.Linear(obs["actor"].shape[1], 256), torch.nn.ELU(), torch.nn.Linear(256, 256), torch.nn.ELU(),
        torch.nn.Linear(256, 128), torch.nn.ELU(), torch.nn.Linear(128, env.num_actions),
    )
    conn.send("ready")
    while steps := conn.recv():
        if world > 1:
            dist.barrier()
        start = time.perf_counter()  # CLOCK_MONOTONIC: comparable across processes
        with torch.inference_mode():
            for _ in range(steps):
                for group, normaliser in normalisers.items():
                    normaliser.update(obs[group])
                mean = actor(normalisers["actor"](obs["actor"]))
                obs = env.step(mean + 0.5 * torch.randn_like(mean))[0]
        conn.send((start, time.perf_counter()))
    if world > 1:
        dist.destroy_process_group()


class Layout:
    """`processes` worker processes of `threads` MuJoCo threads each, sharing `total_envs` robots."""

    def __init__(self, processes: int, threads: int, torch_threads: int, total_envs: int, seed: int):
        self.name = f"{processes} x {threads} thread{'s' if threads > 1 else ''}, torch {torch_threads}"
        self.total_envs = total_envs
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        ctx = mp.get_context("spawn")
        self.conns, self.procs = [], []
        for rank in range(processes):
            parent, child = ctx.Pipe()
            proc = ctx.Process(target=worker, args=(child, rank, processes, port, total_envs // processes, threads,
                                                         torch_threads, seed))
            proc.start()
            self.conns.append(parent)
            self.procs.append(proc)
        for conn in self.conns:
            assert conn.recv() == "ready"

    def env_steps_per_s(self, steps: int) -> float:
        for conn in self.conns:
            conn.send(steps)
        spans = [conn.recv() for conn in self.conns]
        return self.total_envs * steps / (max(end for _, end in spans) - min(start for start, _ in spans))

    def close(self) -> None:
        for conn in self.conns:
            conn.send(0)
        for proc in self.procs:
            proc.join()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--num_envs", type=int, default=4096, help="robots in all, split evenly over the processes")
    parser.add_argument("--processes", type=int, default=2, help="N: processes of one thread against one of N")
    parser.add_argument("--steps", type=int, default=24, help="control steps per timed round (one rollout)")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    n = args.processes
    if args.num_envs % n:
        parser.error(f"--num_envs {args.num_envs} does not split evenly over {n} processes; pick a multiple of {n}")
    load = os.getloadavg()[0]
    layouts = [Layout(1, n, n, args.num_envs, args.seed), Layout(1, n, 1, args.num_envs, args.seed),
               Layout(n, 1, 1, args.num_envs, args.seed)]
    try:
        for layout in layouts:
            layout.env_steps_per_s(2)  # warm up
        rates = {layout.name: [] for layout in layouts}
        for i in range(args.rounds):
            for layout in layouts if i % 2 == 0 else layouts[::-1]:
                rates[layout.name].append(layout.env_steps_per_s(args.steps))
    finally:
        for layout in layouts:
            layout.close()
    print(f"{args.num_envs} robots in all, {args.rounds} rounds of {args.steps} steps, "
          f"{len(os.sched_getaffinity(0))} cores, load average {load:.2f} before, {os.getloadavg()[0]:.2f} after")
    print("processes x MuJoCo threads, torch threads per process: env-steps/s, median (each round)")
    for layout in layouts:
        r = rates[layout.name]
        print(f"  {layout.name:>20}: {statistics.median(r):9,.0f} ({', '.join(f'{x:,.0f}' for x in r)})")
    multi = layouts[-1]
    for single in layouts[:-1]:
        ratio = statistics.median(m / s for m, s in zip(rates[multi.name], rates[single.name]))
        print(f"ratio [{multi.name}] / [{single.name}]: {ratio:.3f} (median of per-round ratios)")

if __name__ == "__main__":
    main()
