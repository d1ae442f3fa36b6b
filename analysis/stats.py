"""Spread across policies: bootstrap intervals and permutation tests for the ablation's comparisons.

The paper's claims compare configurations, each a handful of independently trained policies; the
robots of one policy are repeated measurements of that policy, not independent samples of the
configuration. So both tools treat the policy as the unit:

- `policy_interval`: a two-level bootstrap, policies resampled with replacement and, within each, its
  robots resampled with replacement; the estimate is the mean over policies of a per-policy value.
- `permutation_p`: the configuration labels of the per-policy values shuffled; exact over every
  relabelling when there are few (3 against 3 policies: 20 relabellings, so a one-sided p is never
  below 0.05 — four policies each are the fewest that can show a difference at p < 0.05).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence

import numpy as np

EXACT_LIMIT = 20_000  # relabellings enumerated exactly up to this many; random ones beyond


def policy_interval(per_policy: Sequence[np.ndarray], statistic: Callable = np.mean, level: float = 0.95,
                    resamples: int = 2000, seed: int = 0) -> tuple[float, float, float]:
    """(estimate, low, high): the mean over policies of statistic(robots), with its percentile interval."""
    groups = [np.asarray(g, dtype=float) for g in per_policy]
    if not groups or any(len(g) == 0 for g in groups):
        raise ValueError("every policy needs at least one robot's value")
    estimate = float(np.mean([statistic(g) for g in groups]))
    rng = np.random.default_rng(seed)
    draws = np.empty(resamples)
    for i in range(resamples):
        picked = rng.integers(0, len(groups), len(groups))
        draws[i] = np.mean([statistic(groups[k][rng.integers(0, len(groups[k]), len(groups[k]))]) for k in picked])
    tail = 100 * (1 - level) / 2
    low, high = np.percentile(draws, [tail, 100 - tail])
    return estimate, float(low), float(high)


def permutation_p(a: Sequence[float], b: Sequence[float], alternative: str = "less", resamples: int = 20_000,
                  seed: int = 0) -> float:
    """p-value of mean(a) < mean(b) ('less'), > ('greater') or != ('two-sided'), policies as the unit."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if len(a) == 0 or len(b) == 0:
        raise ValueError("each side needs at least one policy")
    sign = {"less": -1.0, "greater": 1.0, "two-sided": 0.0}[alternative]
    pooled = np.concatenate([a, b])

    def score(first: np.ndarray) -> float:
        diff = first.mean() - (pooled.sum() - first.sum()) / len(b)
        return abs(diff) if sign == 0.0 else sign * diff

    observed = score(a)
    if math.comb(len(pooled), len(a)) <= EXACT_LIMIT:
        scores = [score(pooled[list(idx)]) for idx in itertools.combinations(range(len(pooled)), len(a))]
    else:
        rng = np.random.default_rng(seed)
        scores = [observed] + [score(rng.permutation(pooled)[: len(a)]) for _ in range(resamples)]
    return float(np.mean(np.asarray(scores) >= observed - 1e-12))


def shares(share: float, robots: int) -> np.ndarray:
    """The per-robot 0/1 outcomes behind a share of `robots` (their order does not matter to the bootstrap)."""
    hits = int(round(share * robots))
    return np.repeat([1.0, 0.0], [hits, robots - hits])


def interval_text(estimate: float, low: float, high: float, scale: float = 1.0, digits: int = 2, unit: str = "") -> str:
    return f"{scale * estimate:.{digits}f}{unit} [{scale * low:.{digits}f}, {scale * high:.{digits}f}]"


def verdict(direction_holds: bool, p: float, policies: str) -> str:
    """A claim holds only where the data go its way and p < 0.05 over policies."""
    p_text = f"p = {p:.3f}" if p >= 0.001 else "p < 0.001"
    if not direction_holds:
        return f"no ({p_text}; {policies})"
    return f"{'yes' if p < 0.05 else 'not shown'} ({p_text}; {policies})"
