"""The command envelope: does a policy go where it is told, and which gait does it choose there?

For every command (v_x, v_y, yaw rate) of ENVELOPE the robots start from the default pose with random
oscillator phases at the coupling they were trained with (the evaluation setting of analysis.rollout),
get the command from the first step, and are measured after a start of `warmup_s`: per robot the mean
body-frame v_x, v_y and yaw rate over `measure_s`, the mean absolute error per axis against the
command, the robots that fell, the contact-based gait at the end of the window ("no steps" where no
foot touched down in the window, as a standing robot does; "irregular" where feet step but some leg did not
land in each of the last two RF cycles: a leg held on the ground or in the air, or legs stepping at different
rates), and the step frequency: touchdowns per
second of each foot, averaged over feet and robots (the paper: about 4 Hz at 3 m/s). A command is met when every axis is within
TOLERANCE and no robot fell.

Usage: python -m analysis.envelope [--runs DIR] --out DIR [--quick]
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from analysis import gait
from analysis.plotting import sort_configs, write_csv
from analysis.rollout import EvalSettings, Job, cli_main, run_jobs

# name -> (v_x [m/s], v_y [m/s], yaw rate [rad/s]): the paper's envelope at the points a user tries first.
ENVELOPE: dict[str, tuple[float, float, float]] = {
    "stand": (0.0, 0.0, 0.0),
    "forward 0.5": (0.5, 0.0, 0.0),
    "forward 1": (1.0, 0.0, 0.0),
    "forward 2": (2.0, 0.0, 0.0),
    "forward 3": (3.0, 0.0, 0.0),
    "backward 1": (-1.0, 0.0, 0.0),
    "left 0.5": (0.0, 0.5, 0.0),
    "right 0.5": (0.0, -0.5, 0.0),
    "walk 1, turn left 1": (1.0, 0.0, 1.0),
    "walk 1, turn right 1": (1.0, 0.0, -1.0),
    "turn on the spot left 1.5": (0.0, 0.0, 1.5),
    "turn on the spot right 1.5": (0.0, 0.0, -1.5),
}
TOLERANCE = 0.25  # [m/s or rad/s] per axis, mean absolute error over robots
NO_STEPS = "no steps"
IRREGULAR = "irregular"  # feet step, but no two-cycle window in which every leg lands (gait.rpd_timeseries)
PROTOCOL = {"robots": 16, "warmup_s": 2.0, "measure_s": 8.0}
QUICK = {"robots": 4, "warmup_s": 2.0, "measure_s": 5.0}
PROTOCOL_WINDOW = {k: PROTOCOL[k] for k in ("warmup_s", "measure_s")}  # the protocol's timing, any robot count
FILE_STEM = "envelope"
AXES = ("v_x", "v_y", "yaw_rate")


@dataclass
class CommandResult:
    policy: str
    orc: str
    name: str
    command: tuple[float, float, float]
    robots: int
    tracked: tuple[float, float, float]  # mean over robots and the window
    error: tuple[float, float, float]  # mean over robots of |robot's mean - command|
    falls: int
    gaits: dict[str, float]  # share of robots per contact gait at the end (or NO_STEPS, IRREGULAR)
    alike: bool  # the robots are one sample repeated (Rollout.robots_alike)
    step_frequency: float  # [Hz] touchdowns per second per foot, mean over feet and robots
    # measure(reward_terms=True): each reward term as weighted [1/s], mean over the window and the robots
    # that did not fall; empty otherwise
    rewards: dict[str, float] = field(default_factory=dict)

    @property
    def met(self) -> bool:
        return max(self.error) <= TOLERANCE and self.falls == 0


def command_result(rollout, name: str, command) -> CommandResult:
    lin, ang = rollout.data["base_lin_vel"], rollout.data["base_ang_vel"]
    per_robot = np.stack([lin[..., 0].mean(axis=1), lin[..., 1].mean(axis=1), ang[..., 2].mean(axis=1)], axis=1)
    contact = gait.rpd_timeseries(rollout.data["grf"], dt=rollout.dt)
    steps = np.array([sum(len(td) for td in gait.touchdowns(g, dt=rollout.dt)) / 4 for g in rollout.data["grf"]])
    labels = np.where(contact.valid[:, -1], contact.labels[:, -1], np.where(steps > 0, IRREGULAR, NO_STEPS))
    names, counts = np.unique(labels, return_counts=True)
    seconds = rollout.data["grf"].shape[1] * rollout.dt
    return CommandResult(
        policy=rollout.info.get("run", ""),
        orc=rollout.info.get("orc", ""),
        name=name,
        command=tuple(float(c) for c in command),
        robots=rollout.num_envs,
        tracked=tuple(float(x) for x in per_robot.mean(axis=0)),
        error=tuple(float(x) for x in np.abs(per_robot - np.asarray(command)).mean(axis=0)),
        falls=int(rollout.fell().sum()),
        gaits={str(g): c / len(labels) for g, c in zip(names, counts)},
        alike=rollout.robots_alike(),
        step_frequency=float(np.mean(steps) / seconds),
        rewards=_reward_rates(rollout),
    )


def _reward_rates(rollout) -> dict[str, float]:
    if "reward_terms" not in rollout.data:
        return {}
    stayed_up = ~rollout.fell()
    if not stayed_up.any():
        return {name: float("nan") for name in rollout.info["reward_terms"]}
    rates = rollout.data["reward_terms"][stayed_up].mean(axis=(0, 1))
    return {name: float(rate) for name, rate in zip(rollout.info["reward_terms"], rates)}


def measure(policies, commands: dict[str, tuple[float, float, float]] | None = None, robots: int = QUICK["robots"],
            warmup_s: float = QUICK["warmup_s"], measure_s: float = QUICK["measure_s"],
            settings: EvalSettings = EvalSettings(), seed: int = 0, num_threads: int = 0,
            progress: bool = True, reward_terms: bool = False) -> list[CommandResult]:
    """Every policy at every command (default ENVELOPE), all in shared batches; results per policy, in the
    commands' order. reward_terms: also what each reward term pays (CommandResult.rewards)."""
    commands = ENVELOPE if commands is None else commands
    if measure_s < gait.CHECKPOINT_INTERVAL:
        raise ValueError(f"measure_s={measure_s:g} is shorter than one {gait.CHECKPOINT_INTERVAL:g} s gait checkpoint")
    dt = 1.0 / policies[0].env_cfg.control.frequency_hz
    warmup = int(round(warmup_s / dt))
    jobs = [Job(p, robots, tag=name, command=c) for p in policies for name, c in commands.items()]
    rollouts = run_jobs(jobs, warmup + int(round(measure_s / dt)), settings,
                        record=("grf", "base_lin_vel", "base_ang_vel", "terminated")
                        + (("reward_terms",) if reward_terms else ()), record_from=warmup,
                        seed=seed, num_threads=num_threads, progress=progress, label="envelope")
    return [command_result(r, j.tag, j.command) for j, r in zip(jobs, rollouts)]


def summary_lines(results: list[CommandResult]) -> list[str]:
    """One line per policy and command: tracked velocities, errors, falls, gaits."""
    lines = []
    for r in results:
        tracked = ", ".join(f"{x:+.2f}" for x in r.tracked)
        mark = "met" if r.met else "MISSED"
        lines.append(f"{r.policy} (ORC {r.orc}) | {r.name:26s} | command {r.command} -> ({tracked}) | "
                     f"max error {max(r.error):.2f} | falls {r.falls}/{r.robots} | {gait.mix_text(r.gaits, r.alike)} | "
                     f"{r.step_frequency:.1f} Hz | {mark}")
    return lines


def run(policies, out_dir, quick: bool = False, settings: EvalSettings = EvalSettings(), seed: int = 0,
        progress: bool = True) -> dict:
    """Measure every policy over ENVELOPE and write envelope.csv; return the summary."""
    sizes = QUICK if quick else PROTOCOL
    results = measure(list(policies), settings=settings, seed=seed, progress=progress, **sizes)
    order = {name: k for k, name in enumerate(ENVELOPE)}
    results.sort(key=lambda r: (sort_configs([r.orc]), r.policy, order[r.name]))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = {"csv": write_csv(out / f"{FILE_STEM}.csv",
                              ["policy", "orc", "command_name", *(f"command_{a}" for a in AXES), "robots",
                               *(f"tracked_{a}" for a in AXES), *(f"error_{a}" for a in AXES), "falls", "met",
                               "identical_robots", "gaits", "step_frequency_hz"],
                              ([r.policy, r.orc, r.name, *r.command, r.robots, *(f"{x:.4f}" for x in r.tracked),
                                *(f"{x:.4f}" for x in r.error), r.falls, int(r.met), int(r.alike),
                                gait.mix_text(r.gaits), f"{r.step_frequency:.3f}"] for r in results))}
    if progress:
        print("\n".join(summary_lines(results)), file=sys.stderr)
    return {"files": files, "results": results, "sizes": dict(sizes), "settings": settings.describe()}


def main(argv=None) -> int:
    return cli_main("analysis.envelope", __doc__, run, argv)


if __name__ == "__main__":
    sys.exit(main())
