"""Decentralised phase oscillators (paper eq. for dphi/dt and the (omega, sigma, xi) schedule).

Pure tensor math: no simulator imports, so the dynamics can be tested and plotted on their own.
Leg order everywhere is RF, LF, RH, LH. Phases are in radians, wrapped to [0, 2*pi);
[0, pi) is swing and [pi, 2*pi) is stance. Batched tensors have shape (num_envs, 4);
parameters have shape (num_envs, 1) and broadcast over the legs.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

TWO_PI = 2.0 * math.pi

# Standing parameters of the schedule: a stable fixed point at mid-stance (3*pi/2) for GRF > 0.
STANDING_OMEGA = 1.0
STANDING_COUPLING = 4.0
STANDING_OFFSET = 1.0
# Moving: omega = min(|v| + 1.5, 4) Hz.
MOVING_OMEGA_BIAS = 1.5
MOVING_OMEGA_MAX = 4.0
# Lower clamps applied after the training jitter.
OMEGA_MIN = 0.1
COUPLING_MIN = 0.0

LEG_NAMES = ("RF", "LF", "RH", "LH")

# Ideal relative phases of LF, RH, LH with respect to RF (analysis protocol §3, paper Sec. II-A).
# A leg with RPD r lags RF by r, i.e. phi_j = phi_RF - r (protocol §3, oscillator-based RPD).
IDEAL_RPD = {
    "trot": (math.pi, math.pi, 0.0),
    "pace": (math.pi, 0.0, math.pi),
    "bound": (0.0, math.pi, math.pi),
    "pronk": (0.0, 0.0, 0.0),
}
GAIT_NAMES = tuple(IDEAL_RPD)
PHASE_INIT_MODES = ("random", *GAIT_NAMES, "any_gait", "standing")
# Farther than this (wrapped Euclidean distance in RPD space) from every ideal gait is a transition.
TRANSITION_DISTANCE = 2.0
# What selects the standing schedule: |v_x| alone (paper, released code), or every command component
# ('command'), so that turning on the spot and side steps run the moving schedule instead of sigma = 4
# holding every phase at mid-stance.
STANDING_RULES = ("lin_vel_x", "command")


def standing_speed(command: torch.Tensor, rule: str = "lin_vel_x") -> torch.Tensor:
    """(N,) the speed that oscillator_params compares with stand_threshold: |v_x|, or for 'command' the
    largest of |v_x| [m/s], |v_y| [m/s] and |yaw rate| [rad/s]."""
    if rule == "lin_vel_x":
        return command[:, 0].abs()
    if rule == "command":
        return command.abs().amax(dim=1)
    raise ValueError(f"unknown standing rule {rule!r}; known: {', '.join(STANDING_RULES)}")


def oscillator_velocity(phase, grf, omega, coupling, offset):
    """Phase velocity in rad/s: 2*pi*(omega - sigma*GRF*(cos(phi) + xi)). Broadcasts."""
    return TWO_PI * (omega - coupling * grf * (torch.cos(phase) + offset))


def oscillator_params(
    command_vx: torch.Tensor,
    coupling_max: float = 1.0,
    stand_threshold: float = 0.5,
    omega_noise_std: float = 0.0,
    coupling_noise_std: float = 0.0,
    generator: torch.Generator | None = None,
    coupling_enabled: bool = True,
    stand_speed: torch.Tensor | None = None,
):
    """Schedule (omega [Hz], sigma, xi) from the commanded forward speed; each (num_envs, 1).

    Standing (stand_speed < stand_threshold, strict as in the released code; stand_speed defaults to
    |v|, see standing_speed): (1, 4, 1).
    Moving: (min(|v| + 1.5, 4), coupling_max, 0). The released code used min(1, coupling_max); the two
    agree for coupling_max <= 1, and using it directly lets evaluation sweep sigma above 1.
    Training jitter N(0, std^2) is added to omega and sigma, then omega >= 0.1 and sigma >= 0.
    coupling_enabled=False (ORC C=0) makes sigma exactly 0 everywhere, with no jitter: unlike the
    released code, which kept sigma=4 while standing and a half-normal sigma while moving.
    """
    v = command_vx.reshape(-1, 1)
    if not torch.is_floating_point(v):
        v = v.float()
    speed = v.abs()
    standing = (speed if stand_speed is None else stand_speed.reshape(-1, 1)) < stand_threshold

    omega = torch.where(
        standing,
        torch.full_like(speed, STANDING_OMEGA),
        torch.clamp(speed + MOVING_OMEGA_BIAS, max=MOVING_OMEGA_MAX),
    )
    offset = torch.where(standing, torch.full_like(speed, STANDING_OFFSET), torch.zeros_like(speed))

    # Draw omega's noise first so its random stream does not depend on the coupling toggle.
    if omega_noise_std > 0.0:
        omega = omega + omega_noise_std * _randn_like(speed, generator)
        omega = torch.clamp(omega, min=OMEGA_MIN)

    if not coupling_enabled:
        return omega, torch.zeros_like(speed), offset

    coupling = torch.where(
        standing, torch.full_like(speed, STANDING_COUPLING), torch.full_like(speed, float(coupling_max))
    )
    if coupling_noise_std > 0.0:
        coupling = coupling + coupling_noise_std * _randn_like(speed, generator)
    coupling = torch.clamp(coupling, min=COUPLING_MIN)
    return omega, coupling, offset


def integrate_phases(
    phase: torch.Tensor,
    grf_substeps: torch.Tensor,
    omega,
    coupling,
    offset,
    dt: float,
    process_noise_std: float = 0.0,
    generator: torch.Generator | None = None,
):
    """Explicit Euler over the substep axis of grf_substeps (num_envs, n_substeps, 4).

    Each substep k uses its own GRF and adds 2*pi*eta, eta ~ N(0, process_noise_std^2) [Hz] per leg.
    Returns (phase wrapped to [0, 2*pi), velocity of the last substep in rad/s incl. noise).
    """
    n_sub = grf_substeps.shape[-2]
    if n_sub < 1:
        raise ValueError("grf_substeps needs at least one substep")
    noise = None
    if process_noise_std > 0.0:
        # One draw for all substeps keeps the Python loop free of RNG calls.
        noise = (TWO_PI * process_noise_std) * _randn(
            grf_substeps.shape, grf_substeps.dtype, grf_substeps.device, generator
        )
    vel = None
    for k in range(n_sub):
        vel = oscillator_velocity(phase, grf_substeps[..., k, :], omega, coupling, offset)
        if noise is not None:
            vel = vel + noise[..., k, :]
        phase = torch.remainder(phase + vel * dt, TWO_PI)
    # remainder() can round a tiny negative value up to exactly 2*pi in float32.
    phase = torch.where(phase >= TWO_PI, phase - TWO_PI, phase)
    return phase, vel


def relative_phases(phase: torch.Tensor) -> torch.Tensor:
    """RPD of LF, RH, LH with respect to RF, (..., 3) in [0, 2*pi): (phi_RF - phi_j) mod 2*pi."""
    return torch.remainder(phase[..., :1] - phase[..., 1:], TWO_PI)


def gait_distances(rpd: torch.Tensor) -> torch.Tensor:
    """Wrapped Euclidean distances (..., 4) from RPD vectors (..., 3) to the ideal gaits (GAIT_NAMES order).

    Per component the distance is min(|a - b| mod 2*pi, 2*pi - that), so 6.2 rad is 0.08 from 0.
    """
    ideal = torch.tensor(list(IDEAL_RPD.values()), dtype=rpd.dtype, device=rpd.device)
    d = torch.remainder(torch.abs(rpd.unsqueeze(-2) - ideal), TWO_PI)
    return torch.linalg.vector_norm(torch.minimum(d, TWO_PI - d), dim=-1)


def classify_rpd(rpd: torch.Tensor, max_distance: float = TRANSITION_DISTANCE):
    """(index into GAIT_NAMES, or len(GAIT_NAMES) for a transition; distance to the nearest gait).

    A NaN RPD (no valid measurement) is a transition with distance NaN.
    """
    d = gait_distances(rpd)
    dist, idx = torch.min(torch.nan_to_num(d, nan=float("inf")), dim=-1)
    invalid = torch.isnan(rpd).any(dim=-1)
    dist = torch.where(invalid, torch.full_like(dist, float("nan")), dist)
    idx = torch.where(invalid | (dist > max_distance), torch.full_like(idx, len(GAIT_NAMES)), idx)
    return idx, dist


def initial_phases(
    num_envs: int,
    mode: str = "random",
    generator: torch.Generator | None = None,
    device=None,
    dtype: torch.dtype = torch.float32,
    gait_weights: tuple[float, ...] | None = None,
) -> torch.Tensor:
    """Initial phases (num_envs, 4) in [0, 2*pi).

    'random': i.i.d. U[0, 2*pi) per leg. 'trot'/'pace'/'bound'/'pronk': a random common phase for
    RF plus the ideal relative phases (phi_j = phi_RF - RPD_j). 'any_gait': each robot one of those
    four, uniformly, or in proportion to gait_weights (one per GAIT_NAMES entry). 'standing': all
    legs at 3*pi/2.
    """
    if mode not in PHASE_INIT_MODES:
        raise ValueError(f"unknown phase init mode {mode!r}; valid modes: {', '.join(PHASE_INIT_MODES)}")
    if mode == "standing":
        return torch.full((num_envs, 4), 1.5 * math.pi, dtype=dtype, device=device)
    # Drawn on the generator's device (torch refuses a generator on another), built there, then moved.
    draw_device = generator.device if generator is not None else device
    if mode == "random":
        phase = TWO_PI * torch.rand((num_envs, 4), dtype=dtype, device=draw_device, generator=generator)
    else:
        ideal = torch.tensor([(0.0,) + IDEAL_RPD[g] for g in GAIT_NAMES], dtype=dtype, device=draw_device)
        if mode == "any_gait" and gait_weights is not None:
            cdf = torch.cumsum(torch.tensor(gait_weights, dtype=dtype, device=draw_device), 0)
            draw = cdf[-1] * torch.rand(num_envs, dtype=dtype, device=draw_device, generator=generator)
            which = torch.searchsorted(cdf, draw, right=True).clamp(max=len(GAIT_NAMES) - 1)
            rel = ideal[which]
        elif mode == "any_gait":
            which = torch.randint(len(GAIT_NAMES), (num_envs,), generator=generator, device=draw_device)
            rel = ideal[which]
        else:
            rel = ideal[GAIT_NAMES.index(mode)]
        phase = TWO_PI * torch.rand((num_envs, 1), dtype=dtype, device=draw_device, generator=generator) - rel
        phase = torch.remainder(phase, TWO_PI)
        phase = torch.where(phase >= TWO_PI, phase - TWO_PI, phase)
    return phase.to(device) if device is not None else phase


class FixedPoint(NamedTuple):
    phase: float
    stability: str  # 'stable' | 'unstable' | 'marginal'


def fixed_points(grf: float, omega: float, coupling: float, offset: float, tol: float = 1e-9, probe: float = 1e-4):
    """Fixed points of the noise-free oscillator for constant GRF, sorted by phase in [0, 2*pi).

    Zeros solve cos(phi) = omega/(sigma*GRF) - xi, found in closed form; the label comes from the
    sign of oscillator_velocity just before and after each zero: + then - is 'stable',
    - then + is 'unstable', no sign change (a tangent zero, |cos(phi)| = 1 within tol) is 'marginal'.
    Raises ValueError when every phase is fixed (omega = 0 and sigma*GRF = 0).
    """
    gain = float(coupling) * float(grf)
    omega = float(omega)
    if gain == 0.0:
        if omega == 0.0:
            raise ValueError("omega = 0 and sigma*GRF = 0: every phase is a fixed point")
        return []
    c = omega / gain - float(offset)
    if abs(c) > 1.0 + tol:
        return []
    if abs(abs(c) - 1.0) <= tol:
        roots = [0.0 if c > 0 else math.pi]
    else:
        a = math.acos(c)
        roots = [a, TWO_PI - a]
        # Keep the probes between the two zeros when they nearly merge (|c| close to 1).
        probe = min(probe, 0.25 * min(2.0 * a, TWO_PI - 2.0 * a))

    def vel(p):
        return float(oscillator_velocity(torch.tensor(p, dtype=torch.float64, device="cpu"), grf, omega, coupling, offset))

    out = []
    for r in roots:
        before, after = vel(r - probe), vel(r + probe)
        if before > 0.0 and after < 0.0:
            label = "stable"
        elif before < 0.0 and after > 0.0:
            label = "unstable"
        else:
            label = "marginal"
        out.append(FixedPoint(r, label))
    return sorted(out)


def _randn(shape, dtype, device, generator):
    if generator is None:
        return torch.randn(shape, dtype=dtype, device=device)
    # Draw on the generator's device, then move: torch refuses a generator on another device.
    return torch.randn(shape, dtype=dtype, device=generator.device, generator=generator).to(device)


def _randn_like(x, generator):
    return _randn(x.shape, x.dtype, x.device, generator)

