"""Left-right mirror augmentation for rsl-rl's Symmetry extension (`train.algorithm.symmetry_cfg`).

rsl-rl calls the augmentation function with the VecEnv and a mini-batch; it returns the batch
followed by its mirror image. The maps come from the task (`LeggedRobot.mirror_maps`), which
derives them from the model's geometry.
"""

from __future__ import annotations

import torch
from tensordict import TensorDict


def _mirror(values: torch.Tensor, mirror_map: tuple[torch.Tensor, torch.Tensor]) -> torch.Tensor:
    index, sign = mirror_map
    return values[..., index] * sign


def mirror_augmentation(env, obs: TensorDict | None = None, actions: torch.Tensor | None = None):
    """(obs, actions) with the mirrored samples appended along the batch; None stays None."""
    maps = env.mirror_maps
    if obs is not None:
        mirrored = TensorDict({group: _mirror(obs[group], maps[group]) for group in obs.keys()},
                              batch_size=obs.batch_size, device=obs.device)
        obs = torch.cat([obs, mirrored], dim=0)
    if actions is not None:
        actions = torch.cat([actions, _mirror(actions, maps["actions"])], dim=0)
    return obs, actions
