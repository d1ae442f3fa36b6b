"""Left-right mirror symmetry of a legged robot, as index-and-sign maps (pure numpy, no simulator).

Reflecting a robot through its sagittal plane (y -> -y in the base frame) turns a state of the
robot into another state of the same robot when the model is symmetric: the left legs become the
right ones. A policy can then learn from every sample twice (rsl-rl's symmetry augmentation).
Every map here is `(index, sign)` with `mirrored[..., k] = sign[k] * x[..., index[k]]`, and is
derived from the model's geometry at its home pose, never from joint or foot names.
"""

from __future__ import annotations

import numpy as np

from gym_envs.config import ConfigError

REFLECTION = np.diag([1.0, -1.0, 1.0])
TOLERANCE = 1e-4  # [m] and for unit axes: how far from exact symmetry the home pose may be

# Sign patterns of the 3-vectors an observation term can hold.
VECTOR_SIGNS = (1.0, -1.0, 1.0)  # a polar vector (velocity, gravity direction): y flips
AXIAL_SIGNS = (-1.0, 1.0, -1.0)  # an axial vector (angular velocity): x and z flip
COMMAND_SIGNS = (1.0, -1.0, -1.0)  # (v_x, v_y, yaw rate) commands

Map = tuple[np.ndarray, np.ndarray]


class AsymmetricModelError(ConfigError):
    """The model's home pose is not left-right symmetric, so no mirror map exists."""


def mirror_partners(points: np.ndarray, what: str) -> np.ndarray:
    """Index of each point's mirror image among `points` (N, 3)."""
    points = np.asarray(points, dtype=float)
    reflected = points @ REFLECTION
    distance = np.linalg.norm(points[None, :, :] - reflected[:, None, :], axis=2)  # [i, j]: |p_j - R p_i|
    partner = distance.argmin(axis=1)
    worst = distance[np.arange(len(points)), partner].max(initial=0.0)
    if worst > TOLERANCE or len(set(partner.tolist())) != len(points):
        raise AsymmetricModelError(f"the {what} of the model are not left-right symmetric at the home pose "
                                   f"(largest miss {worst:.2e} m); mirror augmentation needs a symmetric model")
    return partner


def joint_map(anchors: np.ndarray, axes: np.ndarray, default_pos: np.ndarray) -> Map:
    """Mirror map of joint-space vectors (positions relative to the home pose, velocities, targets)."""
    partner = mirror_partners(anchors, "joints")
    # A rotation by q about axis a, reflected, is a rotation by -q about R a (a reflection flips handedness).
    alignment = np.sum(np.asarray(axes)[partner] * (np.asarray(axes) @ REFLECTION), axis=1)
    if not np.allclose(np.abs(alignment), 1.0, atol=TOLERANCE):
        raise AsymmetricModelError("the joint axes of the model are not left-right mirror images; "
                                   "mirror augmentation needs a symmetric model")
    sign = -np.round(alignment)
    default_pos = np.asarray(default_pos, dtype=float)
    if not np.allclose(sign * default_pos[partner], default_pos, atol=TOLERANCE):
        raise AsymmetricModelError("the home keyframe's joint positions are not left-right symmetric; "
                                   "mirror augmentation needs a symmetric home pose")
    return partner, sign


def leg_map(foot_positions: np.ndarray) -> Map:
    """Mirror map of per-leg values (one entry per foot)."""
    partner = mirror_partners(foot_positions, "feet")
    return partner, np.ones(len(partner))


def term_map(kind: str, width: int, joints: Map, legs: Map) -> Map:
    """Mirror map of one observation term of `width` entries.

    kind: 'even' (unchanged by the mirror), 'vector', 'axial', 'command' (3-vectors), 'joints' (one
    entry per joint), or 'legs' (blocks of one entry per leg, e.g. the cos block then the sin block).
    """
    if kind == "even":
        return np.arange(width), np.ones(width)
    signs = {"vector": VECTOR_SIGNS, "axial": AXIAL_SIGNS, "command": COMMAND_SIGNS}
    if kind in signs:
        if width != 3:
            raise ValueError(f"a {kind!r} observation term has 3 entries, not {width}")
        return np.arange(3), np.array(signs[kind])
    blocks = {"joints": joints, "legs": legs}
    if kind not in blocks:
        raise ValueError(f"unknown mirror kind {kind!r}; known: even, vector, axial, command, joints, legs")
    index, sign = blocks[kind]
    if width % len(index):
        raise ValueError(f"a {kind!r} observation term has a multiple of {len(index)} entries, not {width}")
    starts = np.repeat(np.arange(0, width, len(index)), len(index))
    return starts + np.tile(index, width // len(index)), np.tile(sign, width // len(index))


def concatenate(maps: list[Map]) -> Map:
    """The map of the concatenation of vectors with these maps."""
    offsets = np.cumsum([0] + [len(index) for index, _ in maps[:-1]])
    index = np.concatenate([i + o for (i, _), o in zip(maps, offsets)])
    return index, np.concatenate([s for _, s in maps])
