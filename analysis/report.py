"""All figures, CSVs and Table I of the paper from a folder of trained runs, with report.md beside the paper.

Runs are grouped by their ORC configuration (osc.orc of each run's env.yaml). Without --runs the
shipped policies (resources/policies/ORC_<xyz>/seed<k>/) are used. --quick uses the reduced sizes of every
module (a smoke test of the pipeline: its numbers are not comparable with the paper's).

Usage: python -m analysis.report --runs DIR --out DIR [--quick] [--push_slots N]
"""

from __future__ import annotations

import datetime
import math
import subprocess
import sys
from pathlib import Path

import numpy as np

from analysis import (balanced_legs, disturbance, envelope, fixed_points, gait, gait_emergence, obedience, pace_to_trot,
                      stats)
from gym_envs.config import ConfigError
from gym_envs.mini_cheetah_osc import MiniCheetahOscCfg
from gym_envs.orc import PAPER_CONFIGURATIONS
from learning.runs import scan_runs
from analysis.plotting import LEG_NAMES, markdown_table, mean_std_text, sort_configs
from analysis.rollout import (
    DEFAULT_TASK,
    SHIPPED_POLICIES,
    EvalSettings,
    build_parser,
    eval_overrides,
    group_by_orc,
    runs_from_args,
)

# Paper Table I (protocol §10): failure rate [%], mean ± std over 10 policies; (mean, std, bold).
PAPER_TABLE_I = {
    1.5: {"000": (0.0, 0.0, True), "100": (0.0, 0.0, True), "101": (0.1, 0.2, False), "010": (0.0, 0.0, True),
          "110": (0.0, 0.0, True), "011": (0.0, 0.0, True), "111": (0.0, 0.0, True)},
    2.0: {"000": (1.7, 2.5, False), "100": (4.1, 5.2, False), "101": (0.9, 1.2, False), "010": (0.0, 0.0, True),
          "110": (0.0, 0.1, False), "011": (0.0, 0.0, True), "111": (0.0, 0.1, False)},
    2.5: {"000": (11.0, 13.0, False), "100": (10.6, 9.1, False), "101": (7.2, 6.3, False), "010": (0.7, 0.7, False),
          "110": (0.7, 1.0, False), "011": (0.3, 0.4, True), "111": (0.4, 0.4, False)},
    3.0: {"000": (16.3, 12.4, False), "100": (17.5, 8.9, False), "101": (16.0, 10.2, False),
          "010": (3.2, 3.0, False), "110": (4.1, 3.6, False), "011": (3.2, 3.1, False), "111": (2.2, 1.7, True)},
    3.5: {"000": (25.0, 13.5, False), "100": (29.7, 12.7, False), "101": (24.0, 17.1, False),
          "010": (10.6, 8.0, False), "110": (13.8, 7.8, False), "011": (13.1, 9.2, False), "111": (7.4, 4.0, True)},
}
PAPER_SETTLING = {"111_sigma1": "≈ 10 s", "110_sigma1": "nearly 40 s", "111_sigma0": "no convergence"}
PAPER_FINAL_GAITS = {
    "111_sigma0": "final ≈ initial (tracks its initial phases); uniform RPDs give ≈ 46 % Transition",
    "111_sigma1": "mostly trot and pronk in tight clusters (fig. caption: trot and bound)",
    "110_sigma1": "some convergence around trot, more spread out than ORC(111)",
}
# Analytic fixed points at GRF = 0.25, omega = 1 Hz (protocol §7).
EXPECTED_FIXED_POINTS = {
    "sigma4_xi1": "π/2 unstable, 3π/2 = 4.712 stable",
    "sigma4_xi0": "0 ≡ 2π marginal",
    "sigma8_xi0": "stable at 5.236",
    "sigma16_xi0": "stable at 4.965",
    "moving_1mps": "none",
}


# --- formatting -----------------------------------------------------------------------------------


def paper_table_markdown() -> str:
    """Table I as printed in the paper (bold entries as there)."""
    rows = [[f"{m:.1f}", *(mean_std_text(*cells[c]) for c in PAPER_CONFIGURATIONS)]
            for m, cells in PAPER_TABLE_I.items()]
    return markdown_table(["Impulse [m/s]", *PAPER_CONFIGURATIONS], rows)


def _fmt(x, digits: int = 2, unit: str = "") -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    return f"{x:.{digits}f}{unit}"


def _git_commit() -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=10,
                             cwd=Path(__file__).resolve().parent)
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


# --- claims checked on our numbers ----------------------------------------------------------------


def table_claims(rates: dict) -> list[str]:
    """The paper's two Table I claims on rates[config][magnitude] = per-policy failure rates [%], each with a
    one-sided permutation test over policies (stats.verdict: it holds only where p < 0.05)."""
    lines = []
    configs = list(rates)
    magnitudes = sorted({m for c in configs for m in rates[c]})

    def mean(c, m):
        return float(np.mean(rates[c][m]))

    def sizes(*groups):
        return " vs ".join(f"{sum(len(rates[c][m]) for c in g)}" for g in groups) + " policies"

    if "111" in rates and len(configs) > 1:
        for m in [m for m in magnitudes if m >= 3.0]:
            others = [c for c in configs if c != "111"]
            p = max(stats.permutation_p(rates["111"][m], rates[c][m]) for c in others)
            best = min(others, key=lambda c: mean(c, m))
            lines.append(f"ORC(111) lowest at {m:g} m/s (paper: yes): "
                         f"{stats.verdict(mean('111', m) <= mean(best, m), p, sizes(['111'], [best]))}; ORC(111) "
                         f"{mean('111', m):.1f} %, next lowest ORC({best}) {mean(best, m):.1f} % (p: the largest "
                         "against any other configuration)")
    reward = [c for c in ("010", "011") if c in rates]
    obs = [c for c in ("100", "101") if c in rates]
    if reward and obs:
        for m in [m for m in magnitudes if m >= 2.5]:
            r = [v for c in reward for v in rates[c][m]]
            o = [v for c in obs for v in rates[c][m]]
            lines.append(f"phase reward alone ({'/'.join(reward)}) fails less than phase observation alone "
                         f"({'/'.join(obs)}) at {m:g} m/s (paper: yes): "
                         f"{stats.verdict(np.mean(r) < np.mean(o), stats.permutation_p(r, o), sizes(reward, obs))}; "
                         f"{np.mean(r):.1f} % vs {np.mean(o):.1f} %")
    return lines


# --- the report -----------------------------------------------------------------------------------


def build(policies, out_dir, quick: bool = False, settings: EvalSettings = EvalSettings(), seed: int = 0,
          source: str = "", progress: bool = True, push_slots: int | None = None,
          push_command: float | None = None) -> dict:
    """Run every analysis on `policies` (PolicyRun list) and write the figures, CSVs and report.md."""
    policies = [p for p in policies if p.task == DEFAULT_TASK]
    if not policies:
        raise ValueError(f"no {DEFAULT_TASK} runs (env.yaml with osc.orc) to analyse")
    # A push ball that does not fit its test window fails now, not after half an hour of other analyses.
    disturbance.default_ball(quick, push_slots).timeline(1.0 / policies[0].env_cfg.control.frequency_hz)
    disturbance.push_command(policies, push_command)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    started = datetime.datetime.now()

    fp = fixed_points.run(out, quick=quick)
    bl = balanced_legs.run(policies, out, quick, settings, seed, progress=progress)
    collected = gait_emergence.collect(policies, quick, settings, seed, progress=progress)
    ge = gait_emergence.run(policies, out, quick, settings, seed, collected=collected)
    if "111_sigma1" in collected:
        _, policy, rollout = collected["111_sigma1"]
        pt = pace_to_trot.run(policies, out, quick, settings, seed, source=(policy, rollout))
    else:
        pt = {"files": {}, "skipped": "no ORC(111) policy among the runs"}
    del collected
    ob = obedience.run(policies, out, quick, settings, seed, progress=progress)
    ev = envelope.run(policies, out, quick, settings, seed, progress=progress)
    db = disturbance.run(policies, out, quick, settings, seed, push_slots=push_slots, command=push_command,
                         progress=progress)

    results = {"fixed_points": fp, "balanced_legs": bl, "gait_emergence": ge, "pace_to_trot": pt,
               "obedience": ob, "envelope": ev, "disturbance": db}
    text = render(policies, results, quick, settings, seed, source, started)
    report_path = out / "report.md"
    report_path.write_text(text)
    results["report"] = report_path
    return results


def render(policies, results: dict, quick: bool, settings: EvalSettings, seed: int, source: str,
           started: datetime.datetime) -> str:
    groups = group_by_orc(policies)
    configs = sort_configs(groups)
    minutes = (datetime.datetime.now() - started).total_seconds() / 60
    md = ["# orcgym analysis report", ""]
    if quick:
        md += ["> **Quick mode**: reduced sizes (see each section). This checks the pipeline; its numbers are "
               "not comparable with the paper's.", ""]
    md += [
        f"- Policies: {source or 'given programmatically'}; "
        + ", ".join(f"ORC({c}) × {len(groups[c])}" for c in configs),
        f"- Evaluation: {settings.describe()}; deterministic actions; seed {seed}; commit {_git_commit()}; "
        f"{started:%Y-%m-%d %H:%M}, {minutes:.1f} min",
        "- Evaluation overrides applied to each run's env.yaml (protocol §1.6): `"
        + " ".join(eval_overrides(settings, MiniCheetahOscCfg())) + "`",
        "- Falls: a robot's `terminated` flag (trunk contact > 1 N); it is then reset standing with a zero command.",
        "- Gaits: every gait label in this report is **contact-based** unless a column says otherwise: a "
        "touchdown is GRF rising above 0.1 body weight after ≥ 0.05 s unloaded; each touchdown gets its phase "
        "in the RF cycle that holds it; the RPD of a window (the last two complete RF cycles before a "
        "checkpoint) is the circular mean of those phases; nearest ideal gait, Transition beyond a wrapped "
        "distance of 2; a window in which a leg never landed is invalid and counted as Transition "
        "(analysis/gait.py). Oscillator-based labels (phases crossing π) are shown beside them with the "
        "agreement rate.",
        "",
    ]
    sections = {"balanced_legs": _section_balanced, "gait_emergence": _section_emergence, "pace_to_trot": _section_pace,
                "obedience": _section_obedience, "envelope": _section_envelope, "disturbance": _section_disturbance,
                "fixed_points": _section_fixed_points}
    for key, section in sections.items():
        md += section(results[key])
    md += ["## Files", ""]
    for name, res in results.items():
        for key, path in res.get("files", {}).items():
            md.append(f"- {name} / {key}: `{Path(path).name}`")
    fp = results["fixed_points"]  # its files are top-level keys
    for key in ("csv", "points_csv", "png", "pdf"):
        if key in fp:
            md.append(f"- fixed_points / {key}: `{Path(fp[key]).name}`")
    return "\n".join(md) + "\n"


def _section_balanced(bl: dict) -> list[str]:
    s = bl["sizes"]
    md = ["## 1. Balanced leg use (fig. legvariance, protocol §2)", "",
          f"{s['robots_per_policy']} robots per policy, {s['duration_s']:g} s at {s['command_mps']:g} m/s, random "
          "phases; per robot and leg the mean normalised GRF over the whole episode, pooled per configuration. "
          "Figure: `balanced_legs.png`.", ""]
    rows = []
    for c, st in bl["configs"].items():
        robots = f"{st['n']} (all alike)" if st.get("identical_robots") else st["n"]
        rows.append([c, st["policies"], robots, st["falls"],
                     " / ".join(f"{v:.2f}" for v in st["median"]),
                     " / ".join(f"{v:.2f}" for v in st["iqr"]),
                     stats.interval_text(*st["frac_leg_near_zero_interval"], scale=100, digits=0, unit=" %"),
                     stats.interval_text(*st["mean_max_deviation_interval"], digits=3)])
    md += [markdown_table(["ORC", "policies", "robots", "falls", "median ḡ " + "/".join(LEG_NAMES),
                           "IQR " + "/".join(LEG_NAMES), "robots with a leg < 0.05 [95 % interval]",
                           "mean max |ḡ − 0.25| [95 % interval]"], rows), ""]
    md += ["Paper (qualitative): ORC(11x) roughly centred on 0.25 for every leg, ORC(110) slightly wider than "
           "ORC(111); every other configuration wide, with clusters near 0 for at least one leg (2- or 3-legged "
           "gaits).",
           "\"All alike\": the configuration's policies do not observe their oscillators, so under the deterministic "
           "evaluation every robot moves identically; its robots are one sample repeated, not a distribution.", ""]
    inner = [c for c in bl["configs"] if c in ("110", "111")]
    outer = [c for c in bl["configs"] if c not in ("110", "111")]
    if inner and outer:
        dev_in = [v for c in inner for v in bl["configs"][c]["policy_max_deviation"]]
        dev_out = [v for c in outer for v in bl["configs"][c]["policy_max_deviation"]]
        holds = stats.verdict(np.mean(dev_in) < np.mean(dev_out), stats.permutation_p(dev_in, dev_out),
                              f"{len(dev_in)} vs {len(dev_out)} policies")
        md += [f"Here: mean max |ḡ − 0.25| is {np.mean(dev_in):.3f} for ORC(11x) and {np.mean(dev_out):.3f} for the "
               f"others (means over policies); ORC(11x) more balanced (paper: yes): {holds}."]
    return md + [""]


def _section_emergence(ge: dict) -> list[str]:
    md = ["## 2. Gait emergence (figs. rpdPlots, gait111eval111, gait110eval111; protocol §4)", ""]
    if not ge.get("experiments"):
        return md + [f"Skipped: {ge.get('skipped', 'no data')}.", ""]
    s = ge["sizes"]
    md += [f"One policy per configuration (seeded random pick), {s['runs']} runs, {s['duration_s']:g} s at 1 m/s. "
           "Initial gait: the first two complete RF cycles. Settling time: first checkpoint at which ≥ 90 % of runs "
           "show their final gait (not reported when most runs end in Transition). Figures: "
           "`gait_emergence_rpd_scatter.png`, `gait_emergence_distribution_*.png`.", ""]
    rows = []
    for key, e in ge["experiments"].items():
        ended_in_gaits = 1.0 - e["final_fractions"].get("transition", 1.0)
        settling = _fmt(e["settling_time_s"], 0, " s") if ended_in_gaits >= 0.5 else "– (mostly Transition)"
        rows.append([key.replace("_sigma", ", σ = "), e["policy"], settling,
                     PAPER_SETTLING.get(key, "–"), gait.mix_text(e["initial_fractions"]), gait.mix_text(e["final_fractions"]),
                     PAPER_FINAL_GAITS.get(key, "–"), _fmt(e["median_initial_final_distance"]),
                     f"{100 * e['contact_phase_label_agreement']:.0f} %", e["falls"]])
    md += [markdown_table(["experiment", "policy", "settling", "paper settling", "initial gaits", "final gaits",
                           "paper final gaits", "median initial→final RPD distance [rad]",
                           "contact/oscillator label agreement (final)", "falls"], rows), ""]
    return md


def _section_pace(pt: dict) -> list[str]:
    md = ["## 3. Pace to trot (fig. pacetotrot, protocol §5)", ""]
    if pt.get("skipped"):
        return md + [f"Skipped: {pt['skipped']}.", ""]
    sel = pt["selection"]
    md += [f"Run {pt['run']} of the ORC(111), σ = 1 experiment ({pt['policy']}); selection: {sel['rule']} "
           f"({sel['candidates']} strict candidates). Start: {sel['start_label']} (distance to pace "
           f"{_fmt(sel['start_distance_to_pace'])}), at {sel['end_time_s']:g} s: {sel['end_label']} (distance to "
           f"trot {_fmt(sel['end_distance_to_trot'])}). Figure: `pace_to_trot.png`.", "",
           "Share of each leg's GRF inside its own oscillator's stance half [π, 2π) (paper: stance GRF falls between "
           "the π and 0 crossings in every cycle, i.e. ≈ 100 %): "
           + ", ".join(f"{leg} {100 * v:.0f} %" for leg, v in pt["stance_share"].items()), ""]
    return md


def _section_obedience(ob: dict) -> list[str]:
    s = ob["sizes"]
    md = ["## 4. Oscillator obedience (paper: ORC(11x) with σ = 0 \"match their RPD to the oscillator phases\")", "",
          f"Per policy: σ = 0, oscillators started in each ideal gait, {s['robots']} robots per gait, "
          f"{s['duration_s']:g} s at 1 m/s; the share of robots whose contact-based gait at {s['duration_s']:g} s "
          "is the started one (forward velocity over the last 5 s in brackets), the share of GRF impulse inside each "
          "foot's own stance half [π, 2π) (50 % = ignores its oscillator), and how often the contact and oscillator "
          f"labels agree. σ = 1: random phases, {s['settle_robots']} robots, {s['settle_duration_s']:g} s; share in a "
          "regular gait at 10 s, final mix, median time from which a robot stays in one regular gait, share of robots "
          f"with a leg under {100 * obedience.LIGHT_LEG_SHARE:g} % of the load. σ = 0 from random phases, "
          f"{s['free_robots']} robots: median distance between the feet's and the oscillators' RPD at "
          f"{s['duration_s']:g} s (a robot with a leg that never lands counts as not following), contact/oscillator "
          "label agreement in brackets. Figure: `obedience.png`.", ""]
    rows = []
    for r in ob["results"]:
        started = r.started.values()
        if all(x.identical for x in started):
            obeyed = "all robots alike: " + " / ".join(f"{x.gait} {'yes' if x.obeyed else 'no'}" for x in started)
        else:
            obeyed = " / ".join(f"{100 * x.obeyed:.0f} % ({x.velocity:.2f})" for x in started)
        st = r.settling
        rows.append([r.orc, r.policy, obeyed,
                     " / ".join(f"{100 * x.stance_share:.0f} %" for x in started),
                     f"{100 * np.mean([x.phase_agreement for x in started]):.0f} %",
                     f"{100 * st.regular_at_10s:.0f} %", gait.mix_text(st.mix[-1], st.identical), _fmt(st.median_settle_s, 0, " s"),
                     " / ".join(f"{x:.2f}" for x in st.leg_shares), f"{100 * st.light_leg:.0f} %",
                     f"{_fmt(r.free.rpd_distance, 2, ' rad')} ({100 * r.free.label_agreement:.0f} %)",
                     sum(x.falls for x in started) + st.falls + r.free.falls])
    md += [markdown_table(["ORC", "policy", "walks started trot / pace / bound / pronk (v [m/s])",
                           "GRF in stance half", "contact/oscillator agreement", "σ = 1: regular at 10 s",
                           "σ = 1: final gaits", "σ = 1: median settle", "σ = 1: GRF share " + "/".join(LEG_NAMES),
                           f"σ = 1: a leg under {100 * obedience.LIGHT_LEG_SHARE:g} %", "σ = 0, random phases: RPD distance (labels agree)", "falls"],
                          rows), ""]
    regular = {}  # per configuration, the per-policy shares of robots in a regular gait at 10 s under σ = 1
    for r in ob["results"]:
        if np.isfinite(r.settling.regular_at_10s):  # NaN: a rollout shorter than 10 s
            regular.setdefault(r.orc, []).append((r.settling.regular_at_10s, r.settling.robots))
    if not regular:
        return md
    md += ["σ = 1, share of robots in a regular gait at 10 s, mean over policies [95 % interval, policies and "
           "robots resampled]: " + "; ".join(
               f"ORC({c}) " + stats.interval_text(*stats.policy_interval([stats.shares(*x) for x in v]), scale=100,
                                                  digits=0, unit=" %") for c, v in regular.items()), ""]
    if "111" in regular and "110" in regular:
        a, b = ([share for share, _ in regular[c]] for c in ("111", "110"))
        holds = stats.verdict(np.mean(a) > np.mean(b), stats.permutation_p(a, b, "greater"),
                              f"{len(a)} vs {len(b)} policies")
        md += ["ORC(111) settles under coupling faster than ORC(110) (paper: ≈ 10 s against nearly 40 s), read as more "
               f"robots regular at 10 s: {holds}.", ""]
    return md


def _section_envelope(ev: dict) -> list[str]:
    s = ev["sizes"]
    md = ["## 4b. Command envelope (ours; the paper trains v_x, v_y and yaw rate over its whole range)", "",
          f"Per policy and command (v_x, v_y, yaw rate): {s['robots']} robots from random phases at the trained "
          f"coupling, {s['measure_s']:g} s after a {s['warmup_s']:g} s start; the tracked mean of each axis, whether "
          f"every axis is within {envelope.TOLERANCE:g} (m/s or rad/s) with no falls, and the contact gait at the end "
          f"(\"{envelope.NO_STEPS}\": no foot landed, as in standing; \"{envelope.IRREGULAR}\": feet step but some leg "
          "did not land in each of the last two cycles), and each foot's touchdowns per second "
          "(paper: about 4 Hz at 3 m/s). CSV: `envelope.csv`.", ""]
    rows = [[r.orc, r.policy, r.name, " / ".join(f"{x:+.2f}" for x in r.tracked), f"{max(r.error):.2f}",
             "yes" if r.met else "no", r.falls, gait.mix_text(r.gaits, r.alike), f"{r.step_frequency:.1f}"]
            for r in ev["results"]]
    md += [markdown_table(["ORC", "policy", "command", "tracked v_x / v_y / yaw", "max error", "met", "falls",
                           "gait (contacts)", "steps per foot [Hz]"], rows), ""]
    return md


PRE_PUSH_FALLS_LIMIT_PCT = 1.0  # the protocol's bound on robots falling before any push


def _command_note(sizes: dict) -> str:
    if sizes["command_source"] == "trained range":
        return (f" (the protocol's {sizes['protocol_command_mps']:g} m/s lies outside the trained commands; "
                "this is the highest forward command every policy was trained on)")
    if sizes["command_source"] == "requested" and sizes["command_mps"] != sizes["protocol_command_mps"]:
        return f" (--push_command; the protocol's is {sizes['protocol_command_mps']:g} m/s)"
    return ""


def _section_disturbance(db: dict) -> list[str]:
    s = db["sizes"]
    md = ["## 5. Disturbance rejection (Table I, protocol §6)", "",
          f"Per policy and impulse: {s['robots_per_policy_and_impulse']} robots ({s['slots']} slots × "
          f"{s['directions']} directions, {s['direction_mode']} spacing; one slot every {s['slot_interval_s']:g} s "
          f"over {s['push_span_s']:g} s), {s['command_mps']:g} m/s command{_command_note(s)}, "
          f"{s['settle_s']:g} s settling, {s['test_s']:g} s test window; failure = termination from the command "
          "to the second-to-last test sample. Mean ± population std over the policies of each configuration; "
          "bold = lowest mean of the row. Figures: `disturbance_failure_rate.png`, `disturbance_velocity.png`.", "",
          "**This reproduction:**", "", db["table_markdown"], "", "**Paper (Table I):**", "", paper_table_markdown(), ""]
    falls, shares = db["falls_before_push"], db["falls_before_push_pct"]
    over = [c for c, pct in shares.items() if pct >= PRE_PUSH_FALLS_LIMIT_PCT]
    md += ["Falls before the first push (counted as failures, as in the released analysis): "
           + ", ".join(f"ORC({c}) {falls[c]} ({shares[c]:.1f} %)" for c in falls)
           + (f". Above the protocol's {PRE_PUSH_FALLS_LIMIT_PCT:g} % for ORC "
              + ", ".join(over) + ": their failure rates count robots that fell unpushed." if over else "."), ""]
    claims = table_claims(db["rates"])
    if claims:
        md += ["Claims of the paper, checked on these numbers:", ""] + [f"- {line}" for line in claims] + [""]
    return md


def _section_fixed_points(fp: dict) -> list[str]:
    rows = []
    for name, points in fp["fixed_points"].items():
        found = ", ".join(f"{p:.3f} ({s})" for p, s in points) or "none"
        rows.append([name, found, EXPECTED_FIXED_POINTS.get(name, "–")])
    return ["## 6. Oscillator fixed points (fig. offset, protocol §7)", "",
            "Analytic, GRF = 0.25, ω = 1 Hz unless noted. Figure: `oscillator_fixed_points.png`.", "",
            markdown_table(["curve", "fixed points [rad] here", "expected (protocol §7)"], rows), ""]


# --- command line ---------------------------------------------------------------------------------


def main(argv=None) -> int:
    from learning import cli

    parser = build_parser("analysis.report", __doc__, out_default="report", pushes=True)

    def body(args) -> int:
        policies = runs_from_args(args)
        if not any(p.task == DEFAULT_TASK for p in policies):
            raise ConfigError(f"no {DEFAULT_TASK} runs (env.yaml with osc.orc) in {args.runs or 'the shipped policies'}")
        cli.check_writable(args.out)
        source = f"runs in {args.runs}" if args.runs else "shipped policies (resources/policies)"
        skipped = scan_runs(args.runs or SHIPPED_POLICIES)[1]
        if skipped:
            source += " (skipped, not complete runs: " + "; ".join(f"{path}: {lacks}" for path, lacks in skipped) + ")"
        result = build(policies, args.out, quick=args.quick, seed=args.seed, source=source,
                       settings=EvalSettings(process_noise_std=args.process_noise), push_slots=args.push_slots,
                       push_command=args.push_command)
        print(f"report: {result['report']}")
        return 0

    return cli.run(parser, body, argv)


if __name__ == "__main__":
    sys.exit(main())
