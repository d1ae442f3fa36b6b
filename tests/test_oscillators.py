"""Tests for gym_envs.oscillators (dynamics, schedule, integration, init) and the fixed-point figure."""

import csv
import math

import pytest
import torch

from gym_envs.oscillators import (
    PHASE_INIT_MODES,
    TWO_PI,
    fixed_points,
    initial_phases,
    integrate_phases,
    oscillator_params,
    oscillator_velocity,
)

DT = 0.002  # physics substep
N_SUB = 5  # substeps per control step


def _const(n_envs, value):
    return torch.full((n_envs, 1), float(value), dtype=torch.float64)


def _run(phase, grf, omega, sigma, xi, seconds, noise=0.0, generator=None):
    """Integrate with a constant GRF for `seconds`, one control step (5 substeps) per call."""
    n = phase.shape[0]
    grf_sub = torch.full((n, N_SUB, 4), float(grf), dtype=phase.dtype)
    params = [_const(n, v).to(phase.dtype) for v in (omega, sigma, xi)]
    history = []
    for _ in range(int(round(seconds / (DT * N_SUB)))):
        phase, _ = integrate_phases(phase, grf_sub, *params, DT, noise, generator)
        history.append(phase)
    return phase, torch.stack(history)


def _wrapped_error(a, b):
    d = torch.remainder(a - b, TWO_PI)
    return torch.minimum(d, TWO_PI - d)


# --- dynamics ---------------------------------------------------------------------------------


def test_zero_grf_gives_nominal_rate_exactly():
    phase = torch.linspace(0, TWO_PI, 50).reshape(-1, 1).expand(-1, 4)
    omega = torch.tensor([[0.7], [1.0], [2.5], [4.0]]).repeat_interleave(13, 0)[:50]
    vel = oscillator_velocity(phase, torch.zeros_like(phase), omega, 4.0, 1.0)
    assert torch.equal(vel, (TWO_PI * omega).expand_as(phase))


def test_zero_coupling_ignores_grf():
    phase = torch.rand(64, 4) * TWO_PI
    v0 = oscillator_velocity(phase, torch.zeros(64, 4), 2.5, 0.0, 0.0)
    v1 = oscillator_velocity(phase, torch.rand(64, 4), 2.5, 0.0, 0.0)
    assert torch.equal(v0, v1)


def test_velocity_matches_formula_and_broadcasts():
    phase = torch.rand(8, 4, dtype=torch.float64) * TWO_PI
    grf = torch.rand(8, 4, dtype=torch.float64)
    omega, sigma, xi = _const(8, 2.0), _const(8, 1.5), _const(8, 0.5)
    vel = oscillator_velocity(phase, grf, omega, sigma, xi)
    assert vel.shape == (8, 4)
    expected = 2 * math.pi * (2.0 - 1.5 * grf * (torch.cos(phase) + 0.5))
    assert torch.allclose(vel, expected)


# --- fixed points -----------------------------------------------------------------------------


def test_standing_parameters_have_single_stable_point_at_mid_stance():
    fps = fixed_points(0.25, 1.0, 4.0, 1.0)
    stable = [p for p in fps if p.stability == "stable"]
    assert len(stable) == 1 and stable[0].phase == pytest.approx(1.5 * math.pi)
    assert [p.stability for p in fps] == ["unstable", "stable"]
    assert fps[0].phase == pytest.approx(0.5 * math.pi)


def test_random_phases_converge_to_mid_stance():
    gen = torch.Generator().manual_seed(0)
    phase = TWO_PI * torch.rand(256, 4, generator=gen, dtype=torch.float64)
    final, _ = _run(phase, 0.25, 1.0, 4.0, 1.0, seconds=10.0)
    assert _wrapped_error(final, torch.tensor(1.5 * math.pi)).max() < 1e-3


def test_no_offset_fixed_point_is_only_marginal():
    fps = fixed_points(0.25, 1.0, 4.0, 0.0)
    assert len(fps) == 1
    assert fps[0].phase == pytest.approx(0.0) and fps[0].stability == "marginal"
    # dphi/dt = 2*pi*(1 - cos phi) >= 0: it touches zero at 2*pi without changing sign.
    phase = torch.linspace(0, TWO_PI, 1001, dtype=torch.float64)
    assert (oscillator_velocity(phase, 0.25, 1.0, 4.0, 0.0) >= 0).all()


def test_no_offset_does_not_settle_in_stance():
    # From below, the approach to 2*pi is only algebraic (1/eps grows like pi*t), not exponential:
    # after 1 s a 0.3 rad deficit is still > 0.1 rad, where the xi=1 point has contracted e^{-2pi}.
    below = torch.full((1, 4), TWO_PI - 0.3, dtype=torch.float64)
    final, _ = _run(below, 0.25, 1.0, 4.0, 0.0, seconds=1.0)
    assert _wrapped_error(final, torch.tensor(0.0)).min() > 0.1
    near_mid = torch.tensor([[1.5 * math.pi - 0.3, 1.5 * math.pi + 0.3] * 2], dtype=torch.float64)
    final, _ = _run(near_mid, 0.25, 1.0, 4.0, 1.0, seconds=1.0)
    assert _wrapped_error(final, torch.tensor(1.5 * math.pi)).max() < 1e-2

    # Just past the zero, the phase runs away through the whole swing phase.
    past = torch.full((1, 4), 0.05, dtype=torch.float64)
    _, hist = _run(past, 0.25, 1.0, 4.0, 0.0, seconds=10.0)
    assert ((hist > 0.9 * math.pi) & (hist < 1.1 * math.pi)).any()

    # With process noise (as in training), phases near 2*pi are kicked over the edge and leave stance;
    # with xi=1 every phase stays in stance around 3*pi/2.
    gen = torch.Generator().manual_seed(1)
    start = torch.full((200, 4), TWO_PI - 0.1, dtype=torch.float64)
    _, hist = _run(start, 0.25, 1.0, 4.0, 0.0, seconds=5.0, noise=0.25, generator=gen)
    left_stance = (hist < math.pi).any(dim=0)
    assert left_stance.float().mean() > 0.5
    start = torch.full((200, 4), 1.5 * math.pi, dtype=torch.float64)
    _, hist = _run(start, 0.25, 1.0, 4.0, 1.0, seconds=5.0, noise=0.25, generator=gen)
    assert (hist > math.pi).all()


def test_fixed_points_match_protocol_values():
    for sigma, expected in ((8.0, 5.236), (16.0, 4.965), (32.0, 4.838)):
        fps = fixed_points(0.25, 1.0, sigma, 0.0)
        stable = [p.phase for p in fps if p.stability == "stable"]
        assert stable == [pytest.approx(expected, abs=1e-3)]
    assert fixed_points(0.25, 2.5, 1.0, 0.0) == []  # moving: no fixed point
    assert fixed_points(0.0, 1.0, 4.0, 1.0) == []
    with pytest.raises(ValueError):
        fixed_points(0.0, 0.0, 4.0, 1.0)


# --- schedule ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "v, expected",
    [
        (0.0, (1.0, 4.0, 1.0)),
        (0.3, (1.0, 4.0, 1.0)),
        (0.5, (2.0, 1.0, 0.0)),  # strict |v| < 0.5 for standing, as in the released code
        (1.0, (2.5, 1.0, 0.0)),
        (3.0, (4.0, 1.0, 0.0)),
        (-3.0, (4.0, 1.0, 0.0)),
    ],
)
def test_schedule_values(v, expected):
    omega, sigma, xi = oscillator_params(torch.tensor([v]))
    assert omega.shape == sigma.shape == xi.shape == (1, 1)
    assert (omega.item(), sigma.item(), xi.item()) == pytest.approx(expected)


def test_schedule_batched_and_coupling_max():
    v = torch.tensor([0.0, 1.0, 2.0, -0.2])
    omega, sigma, xi = oscillator_params(v, coupling_max=0.5)
    assert omega.shape == (4, 1)
    assert sigma.flatten().tolist() == [4.0, 0.5, 0.5, 4.0]
    assert omega.flatten().tolist() == pytest.approx([1.0, 2.5, 3.5, 1.0])


def test_jitter_statistics_and_clamps():
    gen = torch.Generator().manual_seed(0)
    v = torch.cat([torch.zeros(20000), torch.full((20000,), 1.0)])
    omega, sigma, _ = oscillator_params(v, omega_noise_std=0.25, coupling_noise_std=0.25, generator=gen)
    assert omega[:20000].mean().item() == pytest.approx(1.0, abs=0.01)
    assert omega[:20000].std().item() == pytest.approx(0.25, abs=0.01)
    assert sigma[:20000].mean().item() == pytest.approx(4.0, abs=0.01)
    assert sigma[20000:].std().item() == pytest.approx(0.25, abs=0.02)
    omega, sigma, _ = oscillator_params(v, omega_noise_std=5.0, coupling_noise_std=5.0, generator=gen)
    assert omega.min().item() >= 0.1 and sigma.min().item() >= 0.0
    assert (omega == 0.1).any() and (sigma == 0.0).any()


def test_coupling_disabled_is_zero_everywhere_even_with_jitter():
    v = torch.tensor([0.0, 0.2, -0.4, 0.5, 1.0, 3.0, -3.0] * 100)
    omega_on, sigma_on, _ = oscillator_params(
        v, omega_noise_std=0.25, coupling_noise_std=0.25, generator=torch.Generator().manual_seed(3)
    )
    omega_off, sigma_off, _ = oscillator_params(
        v,
        omega_noise_std=0.25,
        coupling_noise_std=0.25,
        generator=torch.Generator().manual_seed(3),
        coupling_enabled=False,
    )
    assert torch.equal(sigma_off, torch.zeros_like(sigma_off))
    assert (sigma_on > 0).any()
    assert torch.equal(omega_on, omega_off)  # omega's noise does not depend on the toggle


# --- integration ------------------------------------------------------------------------------


def test_per_substep_grf_is_closer_to_fine_reference_than_held_grf():
    n = 64
    phase0 = torch.linspace(0, TWO_PI, n + 1, dtype=torch.float64)[:-1].reshape(-1, 1).repeat(1, 4)
    omega, sigma, xi = _const(n, 1.0), _const(n, 4.0), _const(n, 0.0)

    def grf_at(t):  # GRF ramps 0 -> 1 over one control step, different per leg
        return (t / (N_SUB * DT)) * torch.tensor([1.0, 0.8, 0.6, 0.4], dtype=torch.float64)

    substep_grf = torch.stack([grf_at(k * DT) for k in range(N_SUB)]).expand(n, -1, -1)
    per_sub, _ = integrate_phases(phase0, substep_grf, omega, sigma, xi, DT)
    held, _ = integrate_phases(phase0, substep_grf[:, -1:, :].expand(-1, N_SUB, -1), omega, sigma, xi, DT)

    fine_n = N_SUB * 100
    fine_grf = torch.stack([grf_at(k * DT / 100) for k in range(fine_n)]).expand(n, -1, -1)
    ref, _ = integrate_phases(phase0, fine_grf, omega, sigma, xi, DT / 100)

    err_sub = _wrapped_error(per_sub, ref).max()
    err_held = _wrapped_error(held, ref).max()
    assert _wrapped_error(per_sub, held).max() > 1e-3
    assert err_sub < 0.5 * err_held  # measured: 0.025 vs 0.076 rad


def test_euler_step_and_last_velocity():
    phase = torch.tensor([[0.1, 1.0, 3.0, 6.0]], dtype=torch.float64)
    grf = torch.tensor([[[0.2, 0.4, 0.6, 0.8], [0.1, 0.3, 0.5, 0.7]]], dtype=torch.float64)
    args = (_const(1, 2.0), _const(1, 1.0), _const(1, 0.0))
    new, vel = integrate_phases(phase, grf, *args, DT)
    v0 = oscillator_velocity(phase, grf[:, 0], *args)
    p1 = phase + v0 * DT
    v1 = oscillator_velocity(p1, grf[:, 1], *args)
    assert torch.allclose(vel, v1)
    assert torch.allclose(new, torch.remainder(p1 + v1 * DT, TWO_PI))


def test_process_noise_random_walk():
    gen = torch.Generator().manual_seed(0)
    n = 4000
    phase0 = torch.full((n, 4), 1.0, dtype=torch.float64)
    grf = torch.zeros(n, 500, 4, dtype=torch.float64)  # 1 s of substeps
    final, vel = integrate_phases(phase0, grf, _const(n, 1.0), _const(n, 0.0), _const(n, 0.0), DT, 0.25, gen)
    drift = TWO_PI * 1.0  # 2*pi*omega over 1 s, i.e. one full turn
    disp = torch.remainder(final - phase0 - drift + math.pi, TWO_PI) - math.pi
    # std = 2*pi*0.25*dt*sqrt(500) ~ 0.070 rad per sqrt(s)
    assert disp.std().item() == pytest.approx(2 * math.pi * 0.25 * DT * math.sqrt(500), rel=0.05)
    # The returned velocity is the last substep's, noise included.
    assert (vel - TWO_PI).std().item() == pytest.approx(2 * math.pi * 0.25, rel=0.05)


def test_wrap_stays_in_range():
    # float32 remainder of a tiny negative number rounds to exactly 2*pi; it must be wrapped to 0.
    phase = torch.zeros(1, 4)
    omega = torch.tensor([[1.0 - 2.0**-24]])
    new, _ = integrate_phases(phase, torch.ones(1, 1, 4), omega, torch.ones(1, 1), torch.zeros(1, 1), DT)
    assert (new >= 0).all() and (new < TWO_PI).all()

    gen = torch.Generator().manual_seed(0)
    phase = TWO_PI * torch.rand(2048, 4, generator=gen)
    grf = torch.rand(2048, N_SUB, 4, generator=gen)
    omega = 8 * torch.rand(2048, 1, generator=gen) - 4  # negative rates too
    sigma = 8 * torch.rand(2048, 1, generator=gen)
    for _ in range(20):
        phase, _ = integrate_phases(phase, grf, omega, sigma, torch.ones(2048, 1), 0.01, 1.0, gen)
        assert (phase >= 0).all() and (phase < TWO_PI).all()


# --- initial phases ---------------------------------------------------------------------------

_IDEAL = {
    "trot": (math.pi, math.pi, 0.0),
    "pace": (math.pi, 0.0, math.pi),
    "bound": (0.0, math.pi, math.pi),
    "pronk": (0.0, 0.0, 0.0),
}


@pytest.mark.parametrize("mode", PHASE_INIT_MODES)
def test_initial_phases_modes(mode):
    gen = torch.Generator().manual_seed(0)
    phase = initial_phases(500, mode, generator=gen)
    assert phase.shape == (500, 4)
    assert (phase >= 0).all() and (phase < TWO_PI).all()
    if mode == "standing":
        assert torch.allclose(phase, torch.full_like(phase, 1.5 * math.pi))
    elif mode == "random":
        assert phase.std(dim=0).min() > 1.5  # U[0, 2pi) has std 1.81
    elif mode == "any_gait":
        rpd = torch.remainder(phase[:, :1] - phase[:, 1:], TWO_PI)
        errors = torch.stack([_wrapped_error(rpd, torch.tensor(ideal)).amax(dim=1) for ideal in _IDEAL.values()], dim=1)
        assert errors.min(dim=1).values.max() < 1e-5  # every robot starts in an ideal gait
        counts = torch.bincount(errors.argmin(dim=1), minlength=4)
        assert counts.min() > 500 / 4 * 0.7  # and all four are drawn about equally often
    else:
        rpd = torch.remainder(phase[:, :1] - phase[:, 1:], TWO_PI)  # RPD_j = phi_RF - phi_j
        assert _wrapped_error(rpd, torch.tensor(_IDEAL[mode])).max() < 1e-5
        assert phase[:, 0].std() > 1.5  # the common offset is random


def test_any_gait_draws_the_gaits_in_proportion_to_their_weights():
    phase = initial_phases(4000, "any_gait", generator=torch.Generator().manual_seed(0), gait_weights=(0.0, 1.0, 3.0, 0.0))
    rpd = torch.remainder(phase[:, :1] - phase[:, 1:], TWO_PI)
    errors = torch.stack([_wrapped_error(rpd, torch.tensor(ideal)).amax(dim=1) for ideal in _IDEAL.values()], dim=1)
    shares = torch.bincount(errors.argmin(dim=1), minlength=4) / 4000.0
    assert shares[0] == 0.0 and shares[3] == 0.0  # trot and pronk weigh nothing
    assert shares[2].item() == pytest.approx(0.75, abs=0.03)
    assert initial_phases(0, "any_gait", gait_weights=(1.0, 1.0, 3.0, 1.0)).shape == (0, 4)


def test_initial_phases_unknown_mode():
    with pytest.raises(ValueError, match="gallop") as info:
        initial_phases(4, "gallop")
    for mode in PHASE_INIT_MODES:
        assert mode in str(info.value)


def test_initial_phases_reproducible_with_generator():
    a = initial_phases(10, "random", generator=torch.Generator().manual_seed(5))
    b = initial_phases(10, "random", generator=torch.Generator().manual_seed(5))
    assert torch.equal(a, b)


# --- fixed-point figure -----------------------------------------------------------------------


def test_fixed_point_figure_run(tmp_path):
    from analysis.fixed_points import CURVES, run

    result = run(tmp_path, quick=True)
    for key in ("csv", "png", "pdf"):
        assert result[key].exists() and result[key].stat().st_size > 0
    with open(result["csv"]) as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["phase_rad"] + [c.name for c in CURVES]
    assert float(rows[1][0]) == 0.0 and float(rows[-1][0]) == pytest.approx(TWO_PI)
    # The standing curve (sigma=4, xi=1) is -2*pi*cos(phi).
    col = rows[0].index("sigma4_xi1")
    for row in rows[1:]:
        assert float(row[col]) == pytest.approx(-TWO_PI * math.cos(float(row[0])), abs=1e-6)
    stable = result["fixed_points"]["sigma4_xi1"]
    assert [(round(p, 6), s) for p, s in stable] == [
        (round(0.5 * math.pi, 6), "unstable"),
        (round(1.5 * math.pi, 6), "stable"),
    ]
