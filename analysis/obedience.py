"""Oscillator obedience: does a policy walk the gait its oscillators dictate?

The paper says ORC(11x) policies evaluated with coupling sigma = 0 "match their RPD to the oscillator
phases". Made measurable here, per policy:
  a) obedience: sigma = 0, the four oscillators started in an ideal gait (trot, pace, bound, pronk;
     random common phase), 1 m/s from the first step. With sigma = 0 the oscillators keep that
     pattern, so a policy that uses them walks it. Per started gait: the share of robots whose
     contact-based gait at 10 s is the started one, the oscillator-based label beside it (their
     agreement), the forward velocity over the last 5 s, the share of robots that walk that gait at
     half the command's speed or more (a policy that steps in place in the started gait earns the
     label, not this), and the share of each foot's GRF impulse that falls in its own stance half
     [pi, 2pi).
  b) coupled settling: sigma = 1 (also for policies trained without coupling), random phases, 1 m/s;
     the gait mix every second, the share in a regular gait at 10 s, per robot the time from which
     it stays in one regular gait to the end (median over robots), and the share of robots on which
     one leg carries under LIGHT_LEG_SHARE of the load (a three-legged gait).
  c) free phases: sigma = 0 from random phases, 1 m/s. The oscillators keep whatever pattern they
     were started in, mostly none of the four gaits, so this asks whether a policy follows its
     oscillators outside the ideal-gait starts some recipes train from: per robot at 10 s, the
     distance between the feet's RPD and the oscillators' RPD (median over robots; a leg that never
     touches down makes the robot count as not following) and whether the contact and oscillator
     gait labels agree.
Policies without phase observations cannot see their oscillators: under the deterministic
evaluation their robots are one sample repeated (analysis.rollout), which is reported as such
("identical robots") rather than as a distribution.

Usage: python -m analysis.obedience [--runs DIR] --out DIR [--quick]
"""

from __future__ import annotations

import dataclasses
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis import gait
from analysis.plotting import COLUMN_WIDTH, GAIT_COLORS, paper_style, save_figure, sort_configs, write_csv
from analysis.rollout import EvalSettings, Job, PolicyRun, cli_main, run_jobs

import matplotlib.pyplot as plt  # noqa: E402  (after analysis.plotting selected the Agg backend)

STARTED_GAITS = ("trot", "pace", "bound", "pronk")
PROTOCOL = {"robots": 64, "duration_s": 10.0, "settle_robots": 64, "settle_duration_s": 40.0, "free_robots": 64}
QUICK = {"robots": 16, "duration_s": 10.0, "settle_robots": 16, "settle_duration_s": 20.0, "free_robots": 16}
COMMAND = 1.0  # [m/s]
VELOCITY_WINDOW_S = 5.0  # the forward velocity is averaged over the last this many seconds
GOAL_SHARE = 0.8  # obedience goal: this share of robots walks each started gait, and settles by 10 s
WALKING_FRACTION = 0.5  # a robot walks when its forward velocity is at least this share of the command
LIGHT_LEG_SHARE = 0.05  # a leg carrying less than this share of a robot's total GRF is (nearly) unused
SETTLE_INTERVAL_S = 1.0  # checkpoints of the coupled-settling gait mix (windows of two cycles each)
FILE_STEM = "obedience"


@dataclass
class StartedGait:
    """One policy walking with its oscillators started in one ideal gait, sigma = 0."""

    gait: str
    robots: int
    obeyed: float  # share of robots whose contact gait at the end is `gait`
    walking: float  # share of robots in `gait` at the end moving at >= WALKING_FRACTION of the command
    contact_mix: dict[str, float]  # share of robots per contact label at the end
    phase_agreement: float  # share of robots whose contact and oscillator labels agree at the end
    velocity: float  # mean forward velocity over the last VELOCITY_WINDOW_S [m/s]
    stance_share: float  # GRF impulse in the own stance half, mean over feet and robots
    falls: int
    identical: bool  # the robots are one sample repeated (Rollout.robots_alike: a policy blind to its phases)


@dataclass
class CoupledSettling:
    """One policy at sigma = 1 from random phases."""

    robots: int
    times: list[float]  # checkpoint times [s]
    mix: list[dict[str, float]]  # contact-label shares per checkpoint
    regular_at_10s: float  # share of robots in a regular gait at the 10 s checkpoint
    median_settle_s: float  # median over robots of the settling time (inf: more than half never settle)
    velocity_error: float  # mean |v_x - command| over the last VELOCITY_WINDOW_S [m/s]
    leg_shares: list[float]  # each leg's share of the total GRF (RF, LF, RH, LH), mean over robots
    light_leg: float  # share of robots with a leg under LIGHT_LEG_SHARE of their total GRF
    falls: int
    identical: bool


@dataclass
class FreePhases:
    """One policy at sigma = 0 from random phases: do the feet follow phases that are no ideal gait?"""

    robots: int
    rpd_distance: float  # median over robots of |contact RPD - oscillator RPD| at the end [rad]; inf: most invalid
    invalid: float  # share of robots whose contact RPD is undefined at the end (a leg without touchdown)
    label_agreement: float  # share of robots whose contact and oscillator gait labels agree at the end
    velocity: float  # mean forward velocity over the last VELOCITY_WINDOW_S [m/s]
    falls: int
    identical: bool


@dataclass
class Obedience:
    policy: str
    orc: str
    started: dict[str, StartedGait]
    settling: CoupledSettling | None = None
    free: FreePhases | None = None

    def obeys(self, share: float = GOAL_SHARE) -> bool:
        """The goal of the recipe study: every started gait walked by `share` of the robots, at least
        `share` of the coupled robots in a regular gait at 10 s (when measured), and no falls."""
        started = all(s.walking >= share and s.falls == 0 for s in self.started.values())
        st = self.settling
        return started and (st is None or (st.regular_at_10s >= share and st.falls == 0))

    def summary(self) -> str:
        parts = [f"{g} {100 * s.obeyed:.0f}% ({s.velocity:.2f} m/s, {100 * s.walking:.0f}% walking)"
                 for g, s in self.started.items()]
        text = "obedience " + " / ".join(parts)
        if self.settling is not None:
            st = self.settling
            text += (f" | sigma=1: regular at 10 s {100 * st.regular_at_10s:.0f}%, final "
                     f"{gait.mix_text(st.mix[-1], st.identical)}, median settle {st.median_settle_s:g} s, falls {st.falls}, "
                     f"GRF shares {'/'.join(f'{x:.2f}' for x in st.leg_shares)}, "
                     f"a leg under {LIGHT_LEG_SHARE:g} {100 * st.light_leg:.0f}%")
        if self.free is not None:
            fr = self.free
            text += (f" | sigma=0 random phases: contact-oscillator RPD distance median {fr.rpd_distance:.2f} rad, "
                     f"labels agree {100 * fr.label_agreement:.0f}%, no RPD {100 * fr.invalid:.0f}%, "
                     f"{fr.velocity:.2f} m/s, falls {fr.falls}")
        return text


def _forward_velocity(rollout) -> np.ndarray:
    """(N,) mean forward velocity of each robot over the last VELOCITY_WINDOW_S."""
    window = int(round(VELOCITY_WINDOW_S / rollout.dt))
    return rollout.data["base_lin_vel"][:, -window:, 0].mean(axis=1)


def started_gait_result(rollout, started: str, command: float = COMMAND) -> StartedGait:
    grf, phase = rollout.data["grf"], rollout.data["phase"]
    contact = gait.rpd_timeseries(grf, dt=rollout.dt)
    by_phase = gait.rpd_timeseries(phase, dt=rollout.dt, method="phase")
    final = contact.labels[:, -1]
    velocity = _forward_velocity(rollout)
    return StartedGait(
        gait=started,
        robots=len(grf),
        obeyed=float(np.mean(final == started)),
        walking=float(np.mean((final == started) & (velocity >= WALKING_FRACTION * command))),
        contact_mix={g: float(np.mean(final == g)) for g in gait.GAIT_LABELS},
        phase_agreement=float(gait.agreement(final, by_phase.labels[:, -1])),
        velocity=float(velocity.mean()),
        stance_share=float(np.nanmean(gait.stance_share(phase, grf))),
        falls=int(rollout.fell().sum()),
        identical=rollout.robots_alike(),
    )


def settle_times(times, labels) -> np.ndarray:
    """Per robot, the first checkpoint from which its label stays one regular gait to the end (inf: never)."""
    labels = np.asarray(labels)
    times = np.asarray(times, float)
    out = np.full(len(labels), np.inf)
    for n, row in enumerate(labels):
        if row[-1] == gait.TRANSITION:
            continue
        differs = np.flatnonzero(row != row[-1])
        out[n] = times[differs[-1] + 1] if differs.size else times[0]
    return out


def coupled_settling_result(rollout, command: float = COMMAND) -> CoupledSettling:
    contact = gait.rpd_timeseries(rollout.data["grf"], dt=rollout.dt, interval=SETTLE_INTERVAL_S)
    labels = contact.labels
    at_10 = np.flatnonzero(np.isclose(contact.times, 10.0))
    regular = labels != gait.TRANSITION
    per_leg = rollout.data["grf"].mean(axis=1)  # (N, 4)
    leg_shares = per_leg / per_leg.sum(axis=1, keepdims=True)
    return CoupledSettling(
        robots=len(labels),
        times=[float(t) for t in contact.times],
        mix=[{g: float(np.mean(labels[:, c] == g)) for g in gait.GAIT_LABELS} for c in range(labels.shape[1])],
        regular_at_10s=float(regular[:, at_10[0]].mean()) if at_10.size else float("nan"),
        median_settle_s=float(np.median(settle_times(contact.times, labels))),
        velocity_error=float(np.mean(np.abs(_forward_velocity(rollout) - command))),
        leg_shares=[float(x) for x in leg_shares.mean(axis=0)],
        light_leg=float(np.mean((leg_shares < LIGHT_LEG_SHARE).any(axis=1))),
        falls=int(rollout.fell().sum()),
        identical=rollout.robots_alike(),
    )


def free_phase_result(rollout) -> FreePhases:
    contact = gait.rpd_timeseries(rollout.data["grf"], dt=rollout.dt)
    by_phase = gait.rpd_timeseries(rollout.data["phase"], dt=rollout.dt, method="phase")
    distance = gait.circular_distance(contact.rpd[:, -1], by_phase.rpd[:, -1])
    distance[~contact.valid[:, -1]] = np.inf  # feet without an RPD do not follow the oscillators
    return FreePhases(
        robots=len(distance),
        rpd_distance=float(np.median(distance)),
        invalid=float(np.mean(~contact.valid[:, -1])),
        label_agreement=float(gait.agreement(contact.labels[:, -1], by_phase.labels[:, -1])),
        velocity=float(_forward_velocity(rollout).mean()),
        falls=int(rollout.fell().sum()),
        identical=rollout.robots_alike(),
    )


def measure(policies: list[PolicyRun], robots: int = QUICK["robots"], duration_s: float = QUICK["duration_s"],
            settle_robots: int = QUICK["settle_robots"], settle_duration_s: float = QUICK["settle_duration_s"],
            free_robots: int = 0, settings: EvalSettings = EvalSettings(), seed: int = 0, num_threads: int = 0,
            progress: bool = True, command: float = COMMAND) -> list[Obedience]:
    """Obedience (and, when settle_robots > 0, coupled settling; when free_robots > 0, free phases) of each
    policy; all policies share batches. `command` [m/s] replaces the protocol's 1 m/s forward command (to
    ask at which speeds a gait is held)."""
    dt = 1.0 / policies[0].env_cfg.control.frequency_hz

    def rollouts(n_robots: int, seconds: float, phase_init: str, coupling: float, label: str):
        return run_jobs([Job(p, n_robots) for p in policies], int(round(seconds / dt)),
                        dataclasses.replace(settings, phase_init=phase_init, coupling=coupling),
                        command=(command, 0.0, 0.0), record=("grf", "phase", "base_lin_vel", "terminated"),
                        seed=seed, num_threads=num_threads, progress=progress, label=label)

    started: list[dict[str, StartedGait]] = [{} for _ in policies]
    for g in STARTED_GAITS:
        for i, r in enumerate(rollouts(robots, duration_s, g, 0.0, f"obedience, {g}")):
            started[i][g] = started_gait_result(r, g, command)
    settling: list[CoupledSettling | None] = [None] * len(policies)
    if settle_robots > 0:
        settling = [coupled_settling_result(r, command)
                    for r in rollouts(settle_robots, settle_duration_s, "random", 1.0, "obedience, sigma = 1")]
    free: list[FreePhases | None] = [None] * len(policies)
    if free_robots > 0:
        free = [free_phase_result(r)
                for r in rollouts(free_robots, duration_s, "random", 0.0, "obedience, sigma = 0 from random phases")]
    return [Obedience(p.name, p.orc, s, c, f) for p, s, c, f in zip(policies, started, settling, free)]


def run(policies, out_dir, quick: bool = False, settings: EvalSettings = EvalSettings(), seed: int = 0,
        progress: bool = True) -> dict:
    """Measure every policy, write obedience.csv, obedience_settling.csv and the figure; return the summary."""
    sizes = QUICK if quick else PROTOCOL
    results = measure(list(policies), settings=settings, seed=seed, progress=progress, **sizes)
    results.sort(key=lambda r: (sort_configs([r.orc]), r.policy))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = {
        "csv": write_csv(out / f"{FILE_STEM}.csv",
                         ["policy", "orc", "started_gait", "robots", "obeyed", "walking", "phase_agreement", "velocity_mps",
                          "stance_share", "falls", "identical_robots", *(f"contact_{g}" for g in gait.GAIT_LABELS)],
                         ([r.policy, r.orc, s.gait, s.robots, f"{s.obeyed:.4f}", f"{s.walking:.4f}", f"{s.phase_agreement:.4f}",
                           f"{s.velocity:.4f}", f"{s.stance_share:.4f}", s.falls, int(s.identical),
                           *(f"{s.contact_mix[g]:.4f}" for g in gait.GAIT_LABELS)]
                          for r in results for s in r.started.values())),
        "settling_csv": write_csv(out / f"{FILE_STEM}_settling.csv",
                                  ["policy", "orc", "time_s", "robots", *gait.GAIT_LABELS],
                                  ([r.policy, r.orc, f"{t:g}", r.settling.robots,
                                    *(f"{mix[g]:.4f}" for g in gait.GAIT_LABELS)]
                                   for r in results if r.settling is not None
                                   for t, mix in zip(r.settling.times, r.settling.mix))),
        "policies_csv": write_csv(out / f"{FILE_STEM}_policies.csv",
                                  ["policy", "orc", "obeys", "sigma1_regular_at_10s", "sigma1_median_settle_s",
                                   "sigma1_velocity_error_mps", "sigma1_grf_shares", "sigma1_light_leg",
                                   "free_rpd_distance_median_rad", "free_no_rpd", "free_label_agreement",
                                   "free_velocity_mps", "falls"],
                                  (_policy_row(r) for r in results)),
    }
    with paper_style():
        files.update(save_figure(plot(results), out, FILE_STEM))
    return {"files": files, "results": results, "sizes": dict(sizes), "settings": settings.describe()}


def _policy_row(r: Obedience) -> list:
    """One policy's line of obedience_policies.csv (empty cells for what was not measured)."""
    st, fr = r.settling, r.free
    settling = ([f"{st.regular_at_10s:.4f}", f"{st.median_settle_s:g}", f"{st.velocity_error:.4f}",
                 "/".join(f"{x:.3f}" for x in st.leg_shares), f"{st.light_leg:.4f}"] if st else [""] * 5)
    free = ([f"{fr.rpd_distance:.4f}", f"{fr.invalid:.4f}", f"{fr.label_agreement:.4f}", f"{fr.velocity:.4f}"]
            if fr else [""] * 4)
    falls = sum(s.falls for s in r.started.values()) + (st.falls if st else 0) + (fr.falls if fr else 0)
    return [r.policy, r.orc, int(r.obeys()), *settling, *free, falls]


def plot(results: list[Obedience]):
    """Top: share of robots walking the started gait; bottom: GRF impulse share in the stance half."""
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(COLUMN_WIDTH, 3.9), sharex=True, layout="constrained")
    x = np.arange(len(results))
    width = 0.8 / len(STARTED_GAITS)
    for k, g in enumerate(STARTED_GAITS):
        pos = x - 0.4 + (k + 0.5) * width
        top.bar(pos, [100 * r.started[g].obeyed for r in results], width, color=GAIT_COLORS[g], label=g)
        bottom.bar(pos, [100 * r.started[g].stance_share for r in results], width, color=GAIT_COLORS[g])
    for i, r in enumerate(results):
        if all(s.identical for s in r.started.values()):  # vertical, so neighbouring policies' notes never overlap
            top.text(i, 101, "alike", ha="center", va="bottom", fontsize=5, rotation=90)
    top.set_ylabel("walks the started\ngait at 10 s [%]")
    top.set_ylim(0, 118)
    top.set_title("Oscillators started in a gait\n" r"($\sigma$ = 0, 1 m/s; gaits from foot contacts)")
    fig.legend(ncols=4, frameon=False, loc="outside lower center", handlelength=1.5, columnspacing=1.0)
    bottom.axhline(50, color="0.5", lw=0.6, ls="--")
    bottom.set_ylabel("GRF impulse in\nstance half [%]")
    bottom.set_ylim(0, 100)
    bottom.set_xticks(x)
    # ORC string over training seed, upright while they fit beside each other, else turned.
    bottom.set_xticklabels([f"{r.orc}\n{Path(r.policy).name.replace('seed', 's')}" for r in results],
                           rotation=0 if len(results) <= 12 else 90, fontsize=6)
    bottom.set_xlabel("ORC, training seed (identical robots: alike)")
    return fig


def main(argv=None) -> int:
    return cli_main("analysis.obedience", __doc__, run, argv)


if __name__ == "__main__":
    sys.exit(main())
