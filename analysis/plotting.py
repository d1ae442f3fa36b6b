"""Shared output of the analysis modules: paper column widths, fonts, colours, saving figures and CSVs.

The style is applied in a context (`paper_style()`), never at import, so importing an analysis
module does not change anyone else's matplotlib settings. Figures are written as PNG (for a quick
look) and PDF (for the paper, fonts embedded as TrueType).
"""

from __future__ import annotations

import contextlib
import csv
from pathlib import Path

import matplotlib

from gym_envs.orc import PAPER_CONFIGURATIONS

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

COLUMN_WIDTH = 3.5  # in, one IEEE column
WIDE_WIDTH = 7.0  # in, both columns

LEG_NAMES = ("RF", "LF", "RH", "LH")
LEG_COLORS = ("tab:red", "tab:blue", "tab:orange", "tab:cyan")

# In the order of the paper's Table I (PAPER_CONFIGURATIONS); 111 and 110 get the strong colours of the
# released entropy plots.
CONFIG_COLORS = {
    "000": "cornflowerblue",
    "100": "yellowgreen",
    "101": "tab:brown",
    "010": "mediumpurple",
    "110": "goldenrod",
    "011": "tab:cyan",
    "111": "crimson",
}

GAIT_COLORS = {
    "trot": "tab:blue",
    "pace": "tab:green",
    "bound": "tab:orange",
    "pronk": "tab:purple",
    "transition": "0.75",
}

_STYLE = {
    "font.size": 7,
    "axes.titlesize": 7,
    "axes.labelsize": 7,
    "legend.fontsize": 6,
    "xtick.labelsize": 6,
    "ytick.labelsize": 6,
    "axes.linewidth": 0.6,
    "lines.linewidth": 1.0,
    "pdf.fonttype": 42,
    "ps.fonttype": 42,
    "savefig.dpi": 300,
}


def config_color(orc: str) -> str:
    return CONFIG_COLORS.get(orc, "0.4")


def sort_configs(configs) -> list[str]:
    """Paper order first (Table I), anything else after it, alphabetically."""
    configs = set(configs)
    known = [c for c in PAPER_CONFIGURATIONS if c in configs]
    return known + sorted(configs - set(PAPER_CONFIGURATIONS))


@contextlib.contextmanager
def paper_style():
    with plt.rc_context(_STYLE):
        yield


def save_figure(fig, out_dir, stem: str, dpi: int = 300) -> dict[str, Path]:
    """Write <stem>.png and <stem>.pdf into out_dir, close the figure, return both paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"png": out / f"{stem}.png", "pdf": out / f"{stem}.pdf"}
    fig.savefig(paths["png"], dpi=dpi)
    fig.savefig(paths["pdf"])
    plt.close(fig)
    return paths


def write_csv(path, header, rows) -> Path:
    """Write the header row, then `rows`, as CSV to `path`; returns the path."""
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows(rows)
    return path


def markdown_table(header, rows) -> str:
    """A GitHub markdown table; cells are str()-ed and '|' inside a cell is escaped."""
    def cell(v):
        return str(v).replace("|", "\\|")

    lines = ["| " + " | ".join(cell(h) for h in header) + " |", "|" + "---|" * len(header)]
    for row in rows:
        if len(row) != len(header):
            raise ValueError(f"row {row!r} has {len(row)} cells for {len(header)} columns")
        lines.append("| " + " | ".join(cell(v) for v in row) + " |")
    return "\n".join(lines)


def mean_std_text(mean: float, std: float, bold: bool = False) -> str:
    """A 'mean ± std' table cell with one decimal, as in the paper's Table I; '**...**' when bold."""
    text = f"{mean:.1f} ± {std:.1f}"
    return f"**{text}**" if bold else text
