"""Oscillator fixed-point figure (paper fig. "offset", analysis protocol §7).

Plots dphi/dt [rad/s] against phi in [0, 2*pi] at GRF = 0.25 (a quarter of the body weight per leg),
no noise, for the standing parameters with and without the offset xi, two larger couplings without
offset (showing the stable root moving towards 3*pi/2), and the moving parameters at 1 m/s.
Everything is computed from gym_envs.oscillators, so the figure shows the dynamics that are trained.

Usage: python -m analysis.fixed_points --out results/fixed_points [--quick]
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path

import torch

from analysis.plotting import save_figure, write_csv
from gym_envs.oscillators import fixed_points, oscillator_velocity

import matplotlib.pyplot as plt  # noqa: E402  (after analysis.plotting selected the Agg backend)

GRF = 0.25
FILE_STEM = "oscillator_fixed_points"


@dataclass(frozen=True)
class Curve:
    name: str  # CSV column
    label: str  # legend
    omega: float
    sigma: float
    xi: float
    color: str
    linestyle: str = "-"
    linewidth: float = 1.2


CURVES = (
    Curve("sigma4_xi0", r"$\sigma{=}4,\ \xi{=}0$", 1.0, 4.0, 0.0, "tab:orange"),
    Curve("sigma4_xi1", r"$\sigma{=}4,\ \xi{=}1$ (standing)", 1.0, 4.0, 1.0, "tab:blue", linewidth=1.8),
    Curve("sigma8_xi0", r"$\sigma{=}8,\ \xi{=}0$", 1.0, 8.0, 0.0, "tab:gray", "--", 0.9),
    Curve("sigma16_xi0", r"$\sigma{=}16,\ \xi{=}0$", 1.0, 16.0, 0.0, "k", "--", 0.9),
    Curve("moving_1mps", r"1 m/s: $\omega{=}2.5,\ \sigma{=}1,\ \xi{=}0$", 2.5, 1.0, 0.0, "tab:green", ":", 1.4),
)


def run(out_dir, quick: bool = False) -> dict:
    """Write the CSV, PNG and PDF of the figure into out_dir; return their paths and the fixed points."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    n = 121 if quick else 1441  # both include 0, pi/2, pi, 3pi/2 and 2pi exactly on the grid
    phase = torch.linspace(0.0, 2.0 * math.pi, n, dtype=torch.float64, device="cpu")
    values = {c.name: oscillator_velocity(phase, GRF, c.omega, c.sigma, c.xi) for c in CURVES}
    fps = {c.name: [(p.phase, p.stability) for p in fixed_points(GRF, c.omega, c.sigma, c.xi)] for c in CURVES}

    csv_path = write_csv(out / f"{FILE_STEM}.csv", ["phase_rad"] + [c.name for c in CURVES],
                         ([f"{phase[i].item():.9g}"] + [f"{values[c.name][i].item():.9g}" for c in CURVES]
                          for i in range(n)))
    fp_path = write_csv(out / f"{FILE_STEM}_points.csv", ["curve", "omega_hz", "sigma", "xi", "phase_rad", "stability"],
                        ([c.name, c.omega, c.sigma, c.xi, f"{p:.9g}", s] for c in CURVES for p, s in fps[c.name]))
    figure = save_figure(_plot(phase, values, fps), out, FILE_STEM, dpi=150 if quick else 300)
    return {"csv": csv_path, "points_csv": fp_path, **figure, "fixed_points": fps}


def _plot(phase, values, fps):
    with plt.rc_context({"font.size": 7, "pdf.fonttype": 42, "ps.fonttype": 42}):
        fig, ax = plt.subplots(figsize=(3.5, 3.1), constrained_layout=True)
        ax.axhline(0.0, color="0.3", lw=0.6)
        ax.axvspan(math.pi, 2 * math.pi, color="0.93", zorder=0)  # stance half of the cycle
        for xc, name in ((0.5 * math.pi, "swing"), (1.5 * math.pi, "stance")):
            ax.text(xc, 0.03, name, transform=ax.get_xaxis_transform(), ha="center", va="bottom", color="0.4")
        x = phase.numpy()
        for c in CURVES:
            ax.plot(x, values[c.name].numpy(), color=c.color, ls=c.linestyle, lw=c.linewidth, label=c.label)
            for p, s in fps[c.name]:
                # A zero at phase 0 is the same point as 2*pi: draw it at both ends of the axis.
                for xp in ((p, 2 * math.pi) if p == 0.0 else (p,)):
                    ax.plot(xp, 0.0, "o", ms=4.5, mec=c.color, mew=1.1, zorder=5, clip_on=False,
                            mfc=c.color if s == "stable" else "white")
        # Marker key, separate from the curve colours.
        ax.plot([], [], "o", ms=4.5, mfc="0.45", mec="0.45", label="stable fixed point")
        ax.plot([], [], "o", ms=4.5, mfc="white", mec="0.45", label="unstable / marginal")
        ax.set_xlim(0, 2 * math.pi)
        ax.set_xticks([0, 0.5 * math.pi, math.pi, 1.5 * math.pi, 2 * math.pi])
        ax.set_xticklabels(["0", r"$\pi/2$", r"$\pi$", r"$3\pi/2$", r"$2\pi$"])
        ax.set_xlabel(r"phase $\phi$ [rad]")
        ax.set_ylabel(r"$\dot\phi$ [rad/s]")
        ax.set_title(r"Oscillator dynamics at GRF = 0.25 ($\omega{=}1$ Hz unless noted)", fontsize=7)
        # Below the axes: inside, it would hide the curves' peaks around pi.
        fig.legend(loc="outside lower center", ncols=2, fontsize=6, frameon=False, handlelength=2.4)
    return fig


def build_parser():
    from learning import cli

    parser = cli.Parser("analysis.fixed_points", __doc__)
    parser.add_argument("--out", type=cli.folder, default="results/fixed_points", help="output directory")
    parser.add_argument("--quick", action="store_true", help="coarse grid, low-resolution PNG")
    return parser


def main(argv=None) -> int:
    from learning import cli

    parser = build_parser()

    def body(args) -> int:
        result = run(args.out, quick=args.quick)
        for key in ("csv", "points_csv", "png", "pdf"):
            print(f"{key}: {result[key]}")
        for name, points in result["fixed_points"].items():
            desc = ", ".join(f"{p:.3f} rad ({s})" for p, s in points) or "none"
            print(f"{name}: {desc}")
        return 0

    return cli.run(parser, body, argv)


if __name__ == "__main__":
    sys.exit(main())
