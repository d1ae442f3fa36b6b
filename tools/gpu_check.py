"""GPU check: the checks and figures a short window on a CUDA machine is for, in one command and one log.

    python tools/gpu_check.py --log gpu_check.log                   # on the GPU machine: cuda, 4096 and 8192 robots
    python tools/gpu_check.py --train_minutes 2 --num_envs 4096     # shorter

1. MuJoCo Warp on the device against the CPU backend (mujoco.batch): one control step from the
   same state, the rescue of a blown-up env, and the standing foot forces against the robot's weight.
   PASS/FAIL with the measured differences; the limits are those of tests/test_warp_backend.py.
2. The backend's status line: CUDA graphs on or off, and why.
3. Physics (backend step) and full-env (mini_cheetah_osc step) env-steps/s per robot count
   (bench/sim_throughput.py --sim warp).
4. ORC-111 trained at the paper's settings (train.py --profile paper) for --train_minutes, then
   stopped as Ctrl-C stops it (a checkpoint is saved); its progress lines go into the log.

Exit status 1 when a check failed; a part that raises is logged with its traceback and the next
part still runs. On a machine without CUDA it runs the same steps on Warp's CPU device, which is
what CI's smoke test does with tiny sizes.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
import traceback

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)  # a bare GPU machine has the checkout, not an installed package

import torch  # noqa: E402

from bench import sim_throughput  # noqa: E402
from gym_envs.legged_robot_config import SimCfg, model_file  # noqa: E402
from gym_envs.sim import make_backend  # noqa: E402
from learning.cli import EXIT_INTERRUPTED  # noqa: E402

SUBSTEPS = 5
# Largest differences between the backends after one control step (tests/test_warp_backend.py).
STEP_LIMITS = {"joint_pos": 1e-5, "base_pos": 1e-5, "base_quat": 1e-5, "joint_vel": 2e-4, "base_lin_vel": 2e-4,
               "base_ang_vel": 2e-4, "joint_torques": 1e-4, "foot_forces": 0.01}
WEIGHT_RTOL = 0.05  # summed standing foot forces against the robot's weight


class Tee:
    """Writes to the terminal and the log at once."""

    def __init__(self, *streams):
        self.streams = streams

    def write(self, text):
        for s in self.streams:
            s.write(text)
            s.flush()

    def flush(self):
        for s in self.streams:
            s.flush()


class Checks:
    def __init__(self):
        self.failed = []

    def report(self, name: str, ok: bool, detail: str) -> None:
        print(f"{'PASS' if ok else 'FAIL'} {name}: {detail}", flush=True)
        if not ok:
            self.failed.append(name)

    def run(self, name: str, fn, *args) -> None:
        """One part of the check; an error is logged with its traceback and the next part still runs."""
        try:
            fn(*args)
        except Exception as err:
            print(traceback.format_exc(), end="", flush=True)
            self.report(name, False, f"{type(err).__name__}: {err}")


def backend(name: str, num_envs: int, device: str):
    cfg = SimCfg()
    return make_backend(name, model_path=model_file(cfg.model_path), num_envs=num_envs,
                        foot_sensors=tuple(cfg.foot_sensors), termination_sensors=tuple(cfg.termination_sensors),
                        device=device, num_threads=1)


def hold_home(sim, seconds: float):
    targets = sim.default_joint_pos.to(sim.device).expand(sim.num_envs, -1).clone()
    for _ in range(round(seconds / (sim.timestep * SUBSTEPS))):
        result = sim.step(targets, SUBSTEPS)
    return result


def compare_backends(device: str, checks: Checks) -> None:
    """The Warp backend on `device` against the CPU backend, two robots each."""
    n = 2
    warp_sim, cpu_sim = backend("warp", n, device), backend("mujoco", n, "cpu")  # the first prints its graph status
    standing = hold_home(warp_sim, 2.0)  # fallen from the start height and settled
    total = standing.foot_forces.sum(dim=-1).cpu()
    error = float((total / warp_sim.robot_weight - 1.0).abs().max())
    checks.report("standing foot forces", error <= WEIGHT_RTOL,
                  f"sum of the four within {error:.2%} of the weight {warp_sim.robot_weight:.2f} N (limit {WEIGHT_RTOL:.0%})")

    state = hold_home(cpu_sim, 2.0).state
    zeros = torch.zeros(n, 3)
    for sim in (warp_sim, cpu_sim):
        sim.reset(torch.arange(n, device=sim.device), *(t.to(sim.device) for t in (
            state.base_pos, state.base_quat, zeros, zeros, state.joint_pos, torch.zeros_like(state.joint_pos))))
    gen = torch.Generator().manual_seed(1)
    targets = cpu_sim.default_joint_pos + 0.2 * torch.randn(n, cpu_sim.num_joints, generator=gen)
    w, c = warp_sim.step(targets.to(warp_sim.device), SUBSTEPS), cpu_sim.step(targets, SUBSTEPS)
    for name, limit in STEP_LIMITS.items():
        a, b = (getattr(r if hasattr(r, name) else r.state, name) for r in (w, c))
        diff = float((a.cpu() - b).abs().max())
        checks.report(f"one step: {name}", diff <= limit, f"largest difference {diff:.2e} (limit {limit:.0e})")

    warp_sim._qvel_t[1, :] = 1e12  # a blown-up state, as an unstable simulation produces
    rescued = warp_sim.step(targets.to(warp_sim.device), SUBSTEPS)
    diverged = rescued.diverged.cpu().tolist()
    finite = bool(torch.isfinite(rescued.state.joint_vel).all())
    checks.report("divergence rescue", diverged == [False, True] and finite,
                  f"diverged {diverged} (expected [False, True]), state finite afterwards: {finite}")


def throughput(device: str, num_envs: list[int], steps: int, rounds: int) -> None:
    args = argparse.Namespace(device=device, num_envs=num_envs, substeps=SUBSTEPS, steps=steps, rounds=rounds)
    sim_throughput.bench_warp(args)


def train(device: str, minutes: float, num_envs: int | None, max_iterations: int | None, log_root: str,
          checks: Checks) -> None:
    """train.py at the paper's settings, stopped with SIGINT (a checkpoint is saved) after `minutes`."""
    cmd = [sys.executable, "-u", os.path.join(REPO, "train.py"), "--task", "mini_cheetah_osc", "--orc", "111",
           "--device", device.split(":")[0], "--sim", "warp", "--profile", "paper", "--log_root", log_root]
    for flag, value in (("--num_envs", num_envs), ("--max_iterations", max_iterations)):
        if value:
            cmd += [flag, str(value)]
    print("$ " + " ".join(cmd), flush=True)
    start = time.monotonic()
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    echo = threading.Thread(target=lambda: [print(line, end="", flush=True) for line in proc.stdout])
    echo.start()
    stopped = False
    try:
        proc.wait(timeout=60.0 * minutes)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGINT)  # train.py finishes the iteration, saves and exits
        stopped = True
        proc.wait()
    echo.join()
    ok = proc.returncode == 0 or (stopped and proc.returncode == EXIT_INTERRUPTED)
    checks.report("training", ok, f"train.py exited with status {proc.returncode} after "
                  f"{time.monotonic() - start:.0f} s{' (stopped at the deadline)' if stopped else ''}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default=None, help="torch device of the Warp run (default: cuda:0 when there is one)")
    p.add_argument("--num_envs", type=int, nargs="+", default=[4096, 8192], help="robot counts for the throughput")
    p.add_argument("--steps", type=int, default=50, help="control steps per timed round")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--train_minutes", type=float, default=5.0, help="0 skips the training run")
    p.add_argument("--train_num_envs", type=int, default=None, help="robots of the training run (default: the paper's)")
    p.add_argument("--train_max_iterations", type=int, default=None,
                   help="stop sooner than the minutes if this many iterations are done (default: the paper's 2000)")
    p.add_argument("--log_root", default=os.path.join(REPO, "logs", "gpu_check"), help="folder of the training run")
    p.add_argument("--log", default="gpu_check.log", help="the log of everything printed")
    args = p.parse_args(argv)
    device = args.device or ("cuda:0" if torch.cuda.is_available() else "cpu")
    checks = Checks()
    with open(args.log, "w") as log, contextlib.redirect_stdout(Tee(sys.stdout, log)):
        name = torch.cuda.get_device_name(device) if device.startswith("cuda") else "no CUDA: Warp's CPU device"
        print(f"gpu_check on {device} ({name}), torch {torch.__version__}", flush=True)
        checks.run("backends agree", compare_backends, device, checks)
        checks.run("throughput", throughput, device, args.num_envs, args.steps, args.rounds)
        if args.train_minutes > 0:
            checks.run("training", train, device, args.train_minutes, args.train_num_envs, args.train_max_iterations,
                       args.log_root, checks)
        print(f"checks failed: {', '.join(checks.failed)}" if checks.failed else "all checks passed", flush=True)
    return 1 if checks.failed else 0


if __name__ == "__main__":
    sys.exit(main())
