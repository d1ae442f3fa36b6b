"""Data-parallel training under torchrun, on CPU processes as well as GPUs.

rsl-rl-lib's PPO already averages gradients, KL and normaliser statistics over a torch.distributed
process group; what it fixes that orcgym does not is the group itself (NCCL, `cuda:<local_rank>`).
Here the backend follows the device: gloo for CPU processes, NCCL for GPUs. Each rank simulates
its own robots with its own seed (seed + rank) on its share of the machine's cores; rank 0 alone
writes the run folder.

Setting ORCGYM_SYNC_LOG=<folder> makes every rank append `<iteration> <sha256 of its networks>` to
<folder>/rank<r>.txt after each update, so a test (or a user) can check that the ranks never drift.
"""

from __future__ import annotations

import hashlib
import os
import random
from dataclasses import dataclass

import torch
import torch.distributed as dist

from gym_envs.config import ConfigError

SYNC_LOG_ENV = "ORCGYM_SYNC_LOG"


@dataclass(frozen=True)
class Ranks:
    """Where this process sits in a torchrun launch (all 1/0 when started by plain python)."""

    world_size: int = 1
    rank: int = 0
    local_rank: int = 0
    local_world_size: int = 1

    @property
    def is_distributed(self) -> bool:
        return self.world_size > 1


def ranks_from_env() -> Ranks:
    """This process's ranks from torchrun's environment variables."""
    env = os.environ
    return Ranks(
        world_size=int(env.get("WORLD_SIZE", "1")), rank=int(env.get("RANK", "0")),
        local_rank=int(env.get("LOCAL_RANK", "0")), local_world_size=int(env.get("LOCAL_WORLD_SIZE", "1")),
    )


def resolve_device(requested: str | None, ranks: Ranks) -> str:
    """'cpu', or 'cuda:<local rank>' for --device cuda (one GPU per process on each machine)."""
    if (requested or "cpu") == "cpu":
        return "cpu"
    if not torch.cuda.is_available():
        raise ConfigError("--device cuda, but torch sees no CUDA device (this torch build or machine has none)")
    if ranks.local_rank >= torch.cuda.device_count():
        raise ConfigError(
            f"local rank {ranks.local_rank} needs GPU {ranks.local_rank}, but this machine has "
            f"{torch.cuda.device_count()}; start at most that many processes per machine (--nproc_per_node)"
        )
    return f"cuda:{ranks.local_rank}"


def init_process_group(device: str, ranks: Ranks) -> None:
    """Join torchrun's process group (gloo on CPU, NCCL on CUDA); a no-op for one process."""
    if not ranks.is_distributed or dist.is_initialized():
        return
    if device.startswith("cuda"):
        torch.cuda.set_device(torch.device(device))
        dist.init_process_group("nccl", rank=ranks.rank, world_size=ranks.world_size, device_id=torch.device(device))
    else:
        dist.init_process_group("gloo", rank=ranks.rank, world_size=ranks.world_size)


def shut_down() -> None:
    if dist.is_initialized():
        dist.destroy_process_group()


def barrier() -> None:
    if dist.is_initialized():
        dist.barrier()


def thread_share(ranks: Ranks) -> int:
    """Cores for each process on this machine: all usable cores split evenly, at least one."""
    return max(1, len(os.sched_getaffinity(0)) // ranks.local_world_size)


def shared_random_seed() -> int:
    """A fresh seed drawn by rank 0 and given to every rank (each then adds its rank)."""
    seed = torch.tensor([random.SystemRandom().randrange(10000)], device="cpu")
    if dist.is_initialized():
        if dist.get_backend() == "nccl":
            seed = seed.cuda()
        dist.broadcast(seed, src=0)
    return int(seed.item())


def state_digest(state_dicts: list[dict[str, torch.Tensor]]) -> str:
    """sha256 over every tensor of the state dicts (normaliser statistics included), bit for bit."""
    h = hashlib.sha256()
    for state in state_dicts:
        for name, tensor in state.items():
            h.update(name.encode())
            h.update(tensor.detach().cpu().contiguous().reshape(-1).view(torch.uint8).numpy().tobytes())
    return h.hexdigest()


def log_sync_digest(modules: list[torch.nn.Module], iteration: int, rank: int) -> None:
    """Append this rank's digest of `modules` after `iteration` to $ORCGYM_SYNC_LOG/rank<rank>.txt, if set."""
    folder = os.environ.get(SYNC_LOG_ENV)
    if not folder:
        return
    os.makedirs(folder, exist_ok=True)
    with open(os.path.join(folder, f"rank{rank}.txt"), "a") as f:
        f.write(f"{iteration} {state_digest([m.state_dict() for m in modules])}\n")
