"""Does a policy walk? Velocity tracking, falls and gait of a batch of robots at one command.

The walking check behind bench/time_to_obedience.py and the shipped-policy manifest: robots start from
the default pose with random oscillator phases in the evaluation setting (analysis.rollout), walk
at a fixed forward command, and the measurement window follows a warm-up.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from analysis.gait import CHECKPOINT_INTERVAL, TRANSITION, agreement, label_shares, mix_text, rpd_timeseries
from analysis.rollout import EvalSettings, eval_env_cfg, rollout


@dataclass
class LocomotionCheck:
    tracking_error: float  # mean over robots of |mean forward velocity - command| [m/s]
    mean_velocity: float  # [m/s], over robots and time
    falls: int  # robots that fell at least once in the window
    gaits: dict[str, float]  # share of robots per contact-based gait label at the last 5 s checkpoint
    num_envs: int
    oscillator_gaits: dict[str, float] = field(default_factory=dict)  # the same from the oscillator phases
    agreement: float = float("nan")  # share of robots whose two labels agree
    identical: bool = False  # every robot moved alike (a policy blind to its phases)

    @property
    def regular_share(self) -> float:
        """Share of robots in one of the four ideal gaits (any of them: this is no obedience measure)."""
        return sum(share for g, share in self.gaits.items() if g != TRANSITION)

    def summary(self) -> str:
        return (f"tracking error {self.tracking_error:.3f} m/s (mean v_x {self.mean_velocity:.3f}) | "
                f"falls {self.falls}/{self.num_envs} | gaits (contacts): {mix_text(self.gaits, self.identical)} | "
                f"(oscillators): {mix_text(self.oscillator_gaits)}, agreement {self.agreement:.0%}")


def check_locomotion(policy, env_cfg, command: float = 1.0, warmup_s: float = 2.0, measure_s: float = 10.0,
                     num_envs: int = 16, num_threads: int = 0, seed: int = 0) -> LocomotionCheck:
    if measure_s < CHECKPOINT_INTERVAL:
        raise ValueError(f"measure_s={measure_s} is shorter than one {CHECKPOINT_INTERVAL:g} s gait checkpoint")
    cfg = eval_env_cfg(env_cfg, EvalSettings(), num_envs=num_envs, seed=seed, num_threads=num_threads)
    dt = 1.0 / cfg.control.frequency_hz
    warmup, steps = round(warmup_s / dt), round((warmup_s + measure_s) / dt)
    result = rollout(policy, cfg, steps, command=(command, 0.0, 0.0),
                     record=("grf", "phase", "base_lin_vel", "terminated"), record_from=warmup, progress=False)
    vx = result.data["base_lin_vel"][..., 0]
    labels = rpd_timeseries(result.data["grf"], dt=result.dt).labels[:, -1]
    by_phase = rpd_timeseries(result.data["phase"], dt=result.dt, method="phase").labels[:, -1]
    return LocomotionCheck(
        tracking_error=float(np.mean(np.abs(vx.mean(axis=1) - command))),
        mean_velocity=float(vx.mean()),
        falls=int(result.data["terminated"].any(axis=1).sum()),
        gaits=label_shares(labels),
        num_envs=num_envs,
        oscillator_gaits=label_shares(by_phase),
        agreement=float(agreement(labels, by_phase)),
        identical=result.robots_alike(),
    )
