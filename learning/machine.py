"""Training defaults that fit the machine, and what a run should expect to take.

Without --device, --profile and --sim a run picks: CUDA when torch sees a device, else the CPU; the
paper's settings on CUDA and a CPU recipe on the CPU (`cpu_envelope` for the oscillator task, under
which ORC-111 follows its oscillators over the paper's command envelope; `cpu_fast` for the others); MuJoCo Warp physics on CUDA when
the `gpu` extra is installed, else MuJoCo's CPU batch. A resumed run keeps its own profile and
physics. `choose_defaults` is pure (the caller says whether CUDA and Warp are there), so it is
tested without either.
"""

from __future__ import annotations

import datetime
import importlib.util
from dataclasses import dataclass
from typing import Sequence

# Env steps per second of the CPU recipes' training (1024 robots x 24 steps, [128, 128, 64]), learning and
# checkpoints included, on the idle 2-core development machine (docs/recipe-study.md): 20.9k-23.4k in the
# runs E9 and E12 (350-1000 iterations); with mirror augmentation, whose update is twice as large, 14.0k-14.6k
# (E14 seeds 0 and 1, 1000 and 600 iterations).
CPU_STEPS_PER_S = 22_000
CPU_MIRRORED_STEPS_PER_S = 14_500
CPU_RECIPE_HIDDEN_DIMS = (128, 128, 64)
# With the paper's [256, 256, 128] networks and mirror augmentation (cpu_envelope from E52): 3.5 s per iteration of
# 24,576 env steps at two threads on the same machine (E51), 7.0k env steps/s. On 2026-12-07 the same machine ran
# it alone at 5.0-5.3 s per iteration (four runs): the estimate is the idle rate, a slower host takes longer.
PAPER_HIDDEN_DIMS = (256, 256, 128)
CPU_MIRRORED_PAPER_NETWORK_STEPS_PER_S = 7_000
CPU_RATES = {
    (CPU_RECIPE_HIDDEN_DIMS, False): CPU_STEPS_PER_S,
    (CPU_RECIPE_HIDDEN_DIMS, True): CPU_MIRRORED_STEPS_PER_S,
    (PAPER_HIDDEN_DIMS, True): CPU_MIRRORED_PAPER_NETWORK_STEPS_PER_S,
}
# The paper's settings (4096 robots x 32 steps, [256, 256, 128]) with MuJoCo Warp on one NVIDIA H200, learning and
# checkpoints included: 0.70 s per iteration over 817 iterations of two runs (docs/gpu.md). The only GPU measured.
H200_WARP_STEPS_PER_S = 186_000
CPU_PROFILE, GPU_PROFILE = "cpu_fast", "paper"


def cpu_profile(task: str | None) -> str:
    """The CPU recipe of a task: its registry entry's, else (none named, or the task not known yet) cpu_fast."""
    from gym_envs.registry import TASKS

    return (TASKS[task].cpu_profile if task in TASKS else None) or CPU_PROFILE


def cpu_recipes_text() -> str:
    """The CPU recipes as the help texts quote them, read from the profiles, e.g. '1024 robots x 24 steps:
    cpu_envelope, 1600 iterations, for mini_cheetah_osc; cpu_fast, 300 iterations, for other tasks'."""
    from gym_envs.registry import TASKS
    from learning.runner_config import profile_setting

    def size(name: str) -> str:
        return f"{profile_setting(name, 'env.num_envs')} robots x {profile_setting(name, 'train.num_steps_per_env')} steps"

    parts = [f"{spec.cpu_profile}, {profile_setting(spec.cpu_profile, 'train.max_iterations')} iterations, for {task}"
             for task, spec in TASKS.items() if spec.cpu_profile]
    parts.append(f"{CPU_PROFILE}, {profile_setting(CPU_PROFILE, 'train.max_iterations')} iterations, for other tasks")
    return f"{size(CPU_PROFILE)}: " + "; ".join(parts)


@dataclass(frozen=True)
class RunDefaults:
    device: str  # 'cpu' or 'cuda'
    profile: str | None  # None: no profile (a resumed run keeps its own)
    sim: str | None  # None: the config's (a resumed run's own)
    reasons: tuple[str, ...]  # why each open choice went the way it did
    alternative: str  # the flags that pick the other setting

    def describe(self, physics: str) -> str:
        """The run's first line: the settings, why, and the flag for the other choice."""
        text = f"settings: device {self.device}, profile {self.profile or 'as the run had it'}, physics {physics}"
        if not self.reasons:
            return f"{text} (as given)"
        return f"{text} ({'; '.join(self.reasons)}); {self.alternative}"


def warp_installed() -> bool:
    return all(importlib.util.find_spec(name) is not None for name in ("warp", "mujoco_warp"))


def choose_defaults(device: str | None, profile: str | None, sim: str | None, *, cuda_available: bool,
                    warp_available: bool, resume: bool = False, task: str | None = None) -> RunDefaults:
    """Fill in what the command line left open; the flags given always win."""
    reasons = []
    if device is None:
        device = "cuda" if cuda_available else "cpu"
        reasons.append("torch sees a CUDA device" if cuda_available else "torch sees no CUDA device")
    if profile is None and not resume:
        profile = GPU_PROFILE if device == "cuda" else cpu_profile(task)
        reasons.append("the paper's settings suit a GPU" if profile == GPU_PROFILE
                       else f"{profile} is the CPU recipe" + (f" of {task}" if profile != CPU_PROFILE else ""))
    if sim is None and not resume and device == "cuda":
        sim = "warp" if warp_available else "mujoco"
        reasons.append("MuJoCo Warp is installed" if warp_available
                       else "MuJoCo Warp is not installed: pip install -e \".[gpu]\" keeps physics on the GPU")
    if resume and profile is None:
        reasons.append("a resumed run keeps its own profile and physics")
    if resume:
        alternative = "--device cpu or cuda picks the device"
    elif device == "cuda":
        alternative = f"--device cpu for the CPU recipe (profile {cpu_profile(task)})"
    else:
        alternative = "--profile paper for the paper's settings (4096 robots x 32 steps, 2000 iterations)"
    return RunDefaults(device, profile, sim, tuple(reasons), alternative)


def expected_duration(device: str, sim: str, num_envs: int, steps_per_env: int, iterations: int,
                      world_size: int = 1, mirrored: bool = False,
                      hidden_dims: Sequence[int] = CPU_RECIPE_HIDDEN_DIMS) -> str:
    """One line: the expected wall time of `iterations` PPO iterations, and what the estimate rests on.

    `world_size` processes (torchrun) each step `num_envs` robots; on the CPU they share the cores the rate was
    measured on, so the estimate counts the env steps of all of them. `mirrored`: mirror augmentation doubles
    the update. `hidden_dims`: the actor's layers; on the CPU the networks' size sets much of the rate.
    """
    per_iteration = num_envs * steps_per_env * world_size
    rate = CPU_RATES.get((tuple(hidden_dims), mirrored))
    if device == "cpu" and sim == "mujoco" and rate:
        seconds = iterations * per_iteration / rate
        reference = (f"the idle 2-core development machine's rate with the CPU recipes' 1024 robots x 24 steps, "
                     f"{list(hidden_dims)} networks{' and mirror augmentation' if mirrored else ''}, "
                     f"{rate / 1000:g}k env steps/s")
        return (f"expected duration: about {_human(seconds)} for {iterations} iterations x {per_iteration:,} "
                f"env steps, at {reference} (more cores are faster); the progress lines give this machine's ETA")
    if device == "cuda" and sim == "warp" and world_size == 1:
        seconds = iterations * per_iteration / H200_WARP_STEPS_PER_S
        return (f"expected duration: about {_human(seconds)} for {iterations} iterations x {per_iteration:,} env steps "
                f"at the rate measured on one NVIDIA H200 with the paper's settings, {H200_WARP_STEPS_PER_S / 1000:g}k "
                f"env steps/s (other GPUs differ); the progress lines give this machine's ETA")
    networks = f" and {list(hidden_dims)} networks" if device == "cpu" and sim == "mujoco" else ""
    return (f"expected duration: no measured rate for {device} with {sim} physics{networks} ({iterations} iterations x "
            f"{per_iteration:,} env steps); the progress lines give the ETA from the first iteration")


def _human(seconds: float) -> str:
    if seconds < 90:
        return f"{max(1, round(seconds))} s"
    if seconds < 90 * 60:
        return f"{round(seconds / 60)} min"
    return f"{seconds / 3600:.1f} h ({datetime.timedelta(seconds=round(seconds / 60) * 60)})"
