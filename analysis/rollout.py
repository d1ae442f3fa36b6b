"""Batched evaluation rollouts of trained policies (analysis protocol §1.6, §1.7).

Every analysis module simulates through `run_jobs` (or the lower-level `rollout`): many robots in one
MuJoCo batch, several policies side by side in the same batch when their evaluation configs agree,
a fixed command, optional per-robot velocity impulses, and per-control-step recording of named
signals into numpy arrays.

Evaluation setting (`EvalSettings`, applied to the run's own env.yaml as `section.key=value`
overrides, see `eval_overrides`): no random pushes, no command resampling, no time-outs, friction,
mass and COM randomisation off, reset to the default pose at zero velocity, oscillator ω/σ jitter 0,
actor observation noise off, deterministic actions (the policy callable is expected to return the
mean action). Physics runs on the CPU backend (mujoco.batch, task tensors on the CPU) whatever the run
trained on, so a run trained on a GPU with MuJoCo Warp is analysed on a machine without one; the two
backends agree to 1e-5 after a control step (tests/test_warp_backend.py, tools/gpu_check.py). Command
ranges are all zero, so a robot that falls (its `terminated` flag) is reset standing with a zero command,
as in the released scripts. Oscillator process noise is a switch
(`EvalSettings.process_noise_std`): 0 by default, the authors' evident intent; the released
evaluation scripts actually ran with 0.25 because their switch-off wrote to a misnamed field.

Recording: sample k of a recorded signal is the state right after control step `record_from + k + 1`
(logged once per control step, `Rollout.dt`: the task's, 100 Hz by default). `terminated[n, k]` is
True if robot n ended an episode on that step; the recorded state is then the state after its reset.

One sample repeated: when the policy cannot tell the robots apart (no phase observations, the task's
`robots_indistinguishable`) and robots get the same policy, command and push, they are the same
sample by construction. Their records would still part in floating point (a batch's rows round
differently in the last bit depending on whether a vector or a scalar loop handled them, and contact
dynamics grow that), so how many robots looked "alike", or which gait each showed, would depend on the
processor and the batch size. The rollout therefore records such a group as its first robot's
trajectory, repeated (`Rollout.sample`); the oscillator phases, which depend on each robot's own
initial draw, stay per robot.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np
import torch
import yaml
from tensordict import TensorDict
from tqdm import tqdm

from gym_envs.config import apply_overrides, to_dict
from gym_envs.evaluation import evaluation_overrides
from gym_envs.registry import make_env
from learning.runs import POLICY_ROOT as SHIPPED_POLICIES

DEFAULT_TASK = "mini_cheetah_osc"
DEFAULT_MAX_BATCH = 4096  # robots per MuJoCo batch

Policy = Callable[[TensorDict], torch.Tensor]


# --- policies -----------------------------------------------------------------------------------


@dataclass
class PolicyRun:
    """One trained policy: its deterministic actor and the env config it was trained with.

    `policy(obs)` takes the env's observation TensorDict (groups "actor", "critic") and returns the
    mean action (N, 12). `env_cfg` is the task config rebuilt from the run's env.yaml.
    """

    name: str
    env_cfg: Any
    policy: Policy
    task: str = DEFAULT_TASK
    path: str | None = None
    trained_steps: int = 0  # control steps per env the checkpoint trained (its iteration x steps per iteration)

    @property
    def orc(self) -> str:
        return str(self.env_cfg.osc.orc)


def group_by_orc(runs: Sequence[PolicyRun]) -> dict[str, list[PolicyRun]]:
    """ORC string -> its runs (in the given order)."""
    groups: dict[str, list[PolicyRun]] = {}
    for run in runs:
        groups.setdefault(run.orc, []).append(run)
    return groups


def limit_per_config(runs: Sequence[PolicyRun], max_per_config: int | None) -> list[PolicyRun]:
    """At most max_per_config runs of each ORC configuration, keeping the first ones (None: all)."""
    kept = {id(run) for group in group_by_orc(runs).values() for run in group[:max_per_config]}
    return [run for run in runs if id(run) in kept]


class StackedPolicy:
    """Several policies side by side: rows [offsets[i], offsets[i+1]) of the batch belong to policies[i]."""

    def __init__(self, policies: Sequence[Policy], counts: Sequence[int]):
        if len(policies) != len(counts):
            raise ValueError("one robot count per policy")
        self.policies = list(policies)
        self.offsets = np.concatenate([[0], np.cumsum(counts)]).astype(int)

    def __call__(self, obs: TensorDict) -> torch.Tensor:
        if len(self.policies) == 1:
            return self.policies[0](obs)
        parts = [p(obs[a:b]) for p, a, b in zip(self.policies, self.offsets[:-1], self.offsets[1:])]
        return torch.cat(parts, dim=0)


def load_runs(root: str | None = None) -> list[PolicyRun]:
    """Every run folder under root (a run, an experiment folder, or a log root), loaded for evaluation.

    root=None means the shipped policies (resources/policies/ORC_<xyz>/seed<k>/). The loading itself
    (env config from env.yaml, deterministic actor from the newest checkpoint) is learning's.
    """
    if root is None and not os.path.isdir(SHIPPED_POLICIES):
        raise FileNotFoundError(f"no shipped policies at {SHIPPED_POLICIES}; pass --runs DIR (a sweep's log folder)")
    root = SHIPPED_POLICIES if root is None else root
    if not os.path.isdir(root):
        raise FileNotFoundError(f"runs folder {root} does not exist")
    from learning.runs import scan_runs

    run_dirs, skipped = scan_runs(root)
    for path, lacks in skipped:  # a run still starting, or a damaged one: said, never passed over in silence
        print(f"skipped {path}: {lacks}", file=sys.stderr)
    if not run_dirs:
        raise FileNotFoundError(
            f"no runs in {root}: expected run folders (env.yaml with osc.orc, train.yaml, model_<it>.pt) "
            f"at most two levels down, e.g. {root}/<experiment>/<date>_<run>/"
        )
    return [load_policy_run(d) for d in run_dirs]


def load_policy_run(run_dir: str, checkpoint: int = -1, name: str | None = None) -> PolicyRun:
    """Rebuild a run's env config and deterministic actor (its newest checkpoint, or `checkpoint`) with
    learning's loader; named by its last two folders unless `name` is given."""
    from learning.runs import load_policy

    loaded = load_policy(run_dir, checkpoint)
    return PolicyRun(
        name=name or os.path.relpath(run_dir, os.path.dirname(os.path.dirname(run_dir))),
        env_cfg=loaded.env_cfg,
        policy=loaded.policy,
        task=loaded.task,
        path=run_dir,
        trained_steps=loaded.iteration * loaded.train_cfg.num_steps_per_env,
    )


# --- evaluation config ----------------------------------------------------------------------------


@dataclass(frozen=True)
class EvalSettings:
    phase_init: str = "random"  # gym_envs.oscillators.PHASE_INIT_MODES; i.i.d. U[0, 2pi) per leg
    process_noise_std: float = 0.0  # [Hz] per leg and substep; the released eval scripts ran with 0.25
    observation_noise: bool = False  # actor observation noise (the play script kept it on)
    coupling: float | None = None  # moving coupling sigma at evaluation; None: as trained

    def describe(self) -> str:
        coupling = "as trained" if self.coupling is None else f"{self.coupling:g}"
        return (
            f"phase init {self.phase_init}, process noise {self.process_noise_std:g} Hz, observation noise "
            f"{'on' if self.observation_noise else 'off'}, coupling {coupling}"
        )


def eval_overrides(settings: EvalSettings, cfg) -> list[str]:
    """The `section.key=value` overrides that turn a training config into the evaluation setting.

    Coupling: None keeps the trained value; otherwise only the moving coupling changes
    (osc.coupling_max = sigma, protocol §4), the standing parameters stay. A policy trained with
    C=0 has no coupling at all in this implementation, so sigma > 0 also switches its C bit on;
    O and R are kept, so observations and rewards stay those the policy was trained with.
    """
    overrides = evaluation_overrides(cfg, observation_noise=settings.observation_noise) + [
        f"osc.init={settings.phase_init}",
        f"osc.process_noise_std={float(settings.process_noise_std)!r}",
    ]
    if settings.coupling is not None:
        sigma = float(settings.coupling)
        orc = str(cfg.osc.orc)
        if sigma > 0 and orc[2] == "0":
            overrides.append(f"osc.orc={orc[:2]}1")
        overrides.append(f"osc.coupling_max={sigma!r}")
    return overrides


def eval_env_cfg(run_cfg, settings: EvalSettings, num_envs: int, seed: int = 0, num_threads: int = 0,
                 trained_steps: int = 0):
    """A copy of the run's env config in the evaluation setting, on the CPU backend (the run's config is not
    modified). A checkpoint trained past its second reward stage is paid that stage's rewards from the first
    step (the env switches itself; rewards change what is recorded, never what the robots do)."""
    extra = [f"env.num_envs={int(num_envs)}", f"env.seed={int(seed)}", f"sim.num_threads={int(num_threads)}",
             "env.device=cpu", "sim.backend=mujoco"]
    if 0 < run_cfg.rewards.second_stage.start_step < trained_steps:
        extra.append("rewards.second_stage.start_step=1")
    return apply_overrides(run_cfg, eval_overrides(settings, run_cfg) + extra)


def _cfg_key(task: str, cfg) -> str:
    """Configs that agree up to the batch size and seed can share one batch."""
    data = to_dict(cfg)
    data["env"] = {k: v for k, v in data["env"].items() if k not in ("num_envs", "seed")}
    return task + "\n" + yaml.safe_dump(data, sort_keys=True)


# --- recording ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Signal:
    read: Callable[[Any], torch.Tensor]
    shape: tuple[int, ...] | Callable[[Any], tuple[int, ...]]  # or the env's, where the task decides it
    dtype: Any = np.float32
    doc: str = ""
    per_robot_draw: bool = False  # depends on the robot's own random draw, not only on the policy's inputs


SIGNALS: dict[str, Signal] = {
    "grf": Signal(lambda e: e.grf, (4,), doc="normalised GRF per foot, last substep (RF, LF, RH, LH)"),
    "phase": Signal(lambda e: e.phase, (4,), doc="oscillator phases [rad] in [0, 2pi)", per_robot_draw=True),
    "base_lin_vel": Signal(lambda e: e.base_lin_vel, (3,), doc="trunk linear velocity, body frame [m/s]"),
    "base_ang_vel": Signal(lambda e: e.base_ang_vel, (3,), doc="trunk angular velocity, body frame [rad/s]"),
    "base_height": Signal(lambda e: e.state.base_pos[:, 2], (), doc="trunk height, world z [m]"),
    "command": Signal(lambda e: e.commands, (3,), doc="command (v_x, v_y, yaw rate)"),
    "joint_pos": Signal(lambda e: e.joint_pos, (12,), doc="joint positions [rad]"),
    "terminated": Signal(lambda e: e.terminated, (), np.bool_, doc="the robot fell (trunk contact) on this step"),
    "reward_terms": Signal(lambda e: torch.stack(list(e.reward_terms.values()), dim=1) / e.dt,
                           lambda e: (len(e.reward_terms),), per_robot_draw=True,
                           doc="weighted reward per term [1/s], in the order of Rollout.info['reward_terms']"),
}
DEFAULT_RECORD = ("grf", "phase", "base_lin_vel", "base_height", "terminated")


@dataclass
class Rollout:
    """Recorded signals of one batch of robots; data[name] has shape (N, T, ...)."""

    data: dict[str, np.ndarray]
    initial_phase: np.ndarray  # (N, 4) oscillator phases before the first step
    dt: float  # control step [s]
    num_steps: int
    record_from: int = 0
    info: dict = field(default_factory=dict)
    # sample[n] == sample[m]: robots n and m are one sample repeated (see the module doc); None: all distinct
    sample: np.ndarray | None = None

    def __post_init__(self):
        if self.sample is None:
            self.sample = np.arange(self.num_envs)

    @property
    def num_envs(self) -> int:
        return self.initial_phase.shape[0]

    @property
    def times(self) -> np.ndarray:
        """Time [s] of each recorded sample, counted from the first control step."""
        n = next(iter(self.data.values())).shape[1] if self.data else 0
        return (self.record_from + 1 + np.arange(n)) * self.dt

    def fell(self) -> np.ndarray:
        """(N,) robots that terminated at least once in the recorded window."""
        return self.data["terminated"].any(axis=1)

    def robots_alike(self) -> bool:
        """The robots are one sample repeated: decided from what the policy observes and the inputs each
        robot got, not from the records (module doc)."""
        return bool(self.num_envs > 1 and np.all(self.sample == self.sample[0]))

    def rows(self, index) -> Rollout:
        """The same rollout restricted to some robots."""
        return dataclasses.replace(
            self,
            data={k: v[index] for k, v in self.data.items()},
            initial_phase=self.initial_phase[index],
            info=dict(self.info),
            sample=self.sample[index],
        )


# --- rolling out ----------------------------------------------------------------------------------


def rollout(
    policy: Policy,
    env_cfg,
    num_steps: int,
    command=(1.0, 0.0, 0.0),
    command_step: int = 0,
    record: Sequence[str] = DEFAULT_RECORD,
    record_from: int = 0,
    push_step: np.ndarray | None = None,
    push_delta: np.ndarray | None = None,
    task: str = DEFAULT_TASK,
    progress: bool = True,
    label: str = "rollout",
) -> Rollout:
    """Simulate env_cfg.env.num_envs robots for num_steps control steps under `policy`.

    command (v_x, v_y, yaw rate), or one row per robot, is set before control step `command_step`
    (0: from the start; until then the evaluation command is 0). Robot n gets push_delta[n]
    (world-frame planar velocity, m/s) added to its trunk just before control step push_step[n]
    (negative: never). Signals in `record` (keys of SIGNALS) are kept from step record_from on.
    """
    unknown = [name for name in record if name not in SIGNALS]
    if unknown:
        raise ValueError(f"unknown signals {unknown}; known: {', '.join(SIGNALS)}")
    env = make_env(task, env_cfg)
    n = env.num_envs
    command = torch.as_tensor(np.asarray(command, dtype=np.float32), device=env.device).expand(n, 3)
    pushes = _push_plan(n, push_step, push_delta)

    n_rec = max(num_steps - record_from, 0)
    shapes = {name: SIGNALS[name].shape(env) if callable(SIGNALS[name].shape) else SIGNALS[name].shape
              for name in record}
    buffers = {name: np.zeros((n, n_rec) + shapes[name], SIGNALS[name].dtype) for name in record}
    initial_phase = env.phase.detach().cpu().numpy().copy()
    # A bar on a terminal only; run_jobs prints one summary line per call either way.
    bar = tqdm(total=num_steps, desc=label, unit="step", leave=False, disable=not (progress and sys.stderr.isatty()))
    obs = env.get_observations()
    torch_threads = torch.get_num_threads()
    # The MuJoCo batch has the cores; torch's own thread pool fighting it for them makes the small
    # policy forward passes orders of magnitude slower.
    torch.set_num_threads(1)
    try:
        _loop(env, policy, obs, num_steps, command, command_step, pushes, buffers, record_from, bar)
    finally:
        torch.set_num_threads(torch_threads)
        bar.close()
    sample = _samples(env, policy, command, push_step, push_delta)
    for name, buf in buffers.items():
        if not SIGNALS[name].per_robot_draw:
            buf[:] = buf[sample]
    info = {"reward_terms": list(env.reward_terms)} if "reward_terms" in record else {}
    return Rollout(buffers, initial_phase, env.dt, num_steps, record_from, info=info, sample=sample)


def _samples(env, policy, command: torch.Tensor, push_step, push_delta) -> np.ndarray:
    """Per robot, the first robot it is one sample with: the same policy, command and push, and a policy
    that cannot tell robots apart (the module doc); otherwise itself."""
    n = env.num_envs
    if not env.robots_indistinguishable():
        return np.arange(n)
    counts = np.diff(policy.offsets) if isinstance(policy, StackedPolicy) else [n]
    inputs = [np.repeat(np.arange(len(counts)), counts)[:, None], command.cpu().numpy()]
    if push_step is not None:
        inputs += [np.asarray(push_step, float)[:, None], np.asarray(push_delta, float)]
    _, first, group = np.unique(np.concatenate(inputs, axis=1), axis=0, return_index=True, return_inverse=True)
    return first[group.reshape(-1)]


def _loop(env, policy, obs, num_steps, command, command_step, pushes, buffers, record_from, bar) -> None:
    with torch.inference_mode():
        for k in range(num_steps):
            if k == command_step:
                env.commands[:] = command
                obs = env.get_observations()  # the command is part of the observation
            if k in pushes:
                ids, delta = pushes[k]
                env.sim.push_base(ids, delta)
            obs, _, _, _ = env.step(policy(obs))
            if k >= record_from:
                for name, buf in buffers.items():
                    buf[:, k - record_from] = SIGNALS[name].read(env).detach().cpu().numpy()
            bar.update(1)


def _push_plan(n, push_step, push_delta) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    if push_step is None:
        return {}
    push_step = np.asarray(push_step, dtype=int)
    push_delta = np.asarray(push_delta, dtype=float)
    if push_step.shape != (n,) or push_delta.shape != (n, 2):
        raise ValueError(f"push_step must be ({n},) and push_delta ({n}, 2), got {push_step.shape}, {push_delta.shape}")
    ids = {int(step): np.flatnonzero(push_step == step) for step in np.unique(push_step[push_step >= 0])}
    return {step: (robots, push_delta[robots]) for step, robots in ids.items()}


@dataclass
class Job:
    """num_envs robots of one policy, optionally with a per-robot push schedule (see `rollout`) and a
    command of its own (v_x, v_y, yaw rate) instead of run_jobs' common one."""

    run: PolicyRun
    num_envs: int
    push_step: np.ndarray | None = None
    push_delta: np.ndarray | None = None
    tag: Any = None  # free label for the caller (e.g. the push magnitude)
    command: tuple[float, float, float] | None = None


def run_jobs(
    jobs: Sequence[Job],
    num_steps: int,
    settings: EvalSettings = EvalSettings(),
    command=(1.0, 0.0, 0.0),
    command_step: int = 0,
    record: Sequence[str] = DEFAULT_RECORD,
    record_from: int = 0,
    seed: int = 0,
    max_batch: int = DEFAULT_MAX_BATCH,
    num_threads: int = 0,
    progress: bool = True,
    label: str = "rollout",
) -> list[Rollout]:
    """Roll out every job; returns one Rollout per job, in order.

    Jobs whose evaluation configs agree share MuJoCo batches of at most max_batch robots (a job is
    never split); batch b is seeded with seed + b, so results are reproducible for the same jobs.
    """
    # The reward stage only where rewards are recorded: elsewhere it would split batches (and their draws) by
    # checkpoint for nothing.
    paid = "reward_terms" in record
    cfgs = [eval_env_cfg(j.run.env_cfg, settings, j.num_envs, seed, num_threads, j.run.trained_steps if paid else 0)
            for j in jobs]
    keys = [_cfg_key(j.run.task, c) for j, c in zip(jobs, cfgs)]
    batches = [batch for key in dict.fromkeys(keys) for batch in pack_batches(
        [i for i, k in enumerate(keys) if k == key], lambda i: jobs[i].num_envs, max_batch)]

    results: list[Rollout | None] = [None] * len(jobs)
    start = time.perf_counter()
    for b, members in enumerate(batches):
        counts = [jobs[i].num_envs for i in members]
        total = sum(counts)
        cfg = apply_overrides(cfgs[members[0]], [f"env.num_envs={total}", f"env.seed={seed + b}"])
        push_step, push_delta = _stack_pushes([jobs[i] for i in members])
        commands = np.concatenate([np.tile(np.asarray(command if jobs[i].command is None else jobs[i].command,
                                                      dtype=np.float32), (jobs[i].num_envs, 1)) for i in members])
        tag = f"{label}, batch {b + 1}/{len(batches)}" if len(batches) > 1 else label
        policy = StackedPolicy([jobs[i].run.policy for i in members], counts)
        out = rollout(policy, cfg, num_steps, commands, command_step, record, record_from, push_step, push_delta,
                      jobs[members[0]].run.task, progress, f"{tag} ({total} robots)")
        for i, a, z in zip(members, policy.offsets[:-1], policy.offsets[1:]):
            part = out.rows(slice(a, z))
            part.info.update(run=jobs[i].run.name, orc=jobs[i].run.orc, tag=jobs[i].tag, seed=seed + b,
                             settings=settings)
            results[i] = part
    if progress:
        robots = sum(j.num_envs for j in jobs)
        print(f"{label}: {len(jobs)} jobs, {robots} robots x {num_steps} steps in {len(batches)} batches, "
              f"{time.perf_counter() - start:.0f} s", file=sys.stderr, flush=True)
    return results  # type: ignore[return-value]


def pack_batches(items: Sequence, size: Callable[[Any], int], max_batch: int) -> list[list]:
    """The items in order, in consecutive groups whose sizes add up to at most max_batch (an item is never split)."""
    groups, total = [[]], 0
    for item in items:
        if groups[-1] and total + size(item) > max_batch:
            groups.append([])
            total = 0
        groups[-1].append(item)
        total += size(item)
    return groups


def _stack_pushes(jobs: Sequence[Job]):
    if all(j.push_step is None for j in jobs):
        return None, None
    steps = [np.full(j.num_envs, -1) if j.push_step is None else np.asarray(j.push_step, dtype=int) for j in jobs]
    deltas = [np.zeros((j.num_envs, 2)) if j.push_step is None else np.asarray(j.push_delta, dtype=float)
              for j in jobs]
    return np.concatenate(steps), np.concatenate(deltas)


# --- command line shared by the analysis modules ---------------------------------------------------


def build_parser(prog: str, description: str, out_default: str | None = None, pushes: bool = False):
    """The flags every analysis module takes (learning.cli's style and checks); `pushes` adds Table I's size."""
    from learning import cli

    parser = cli.Parser(prog, description)
    parser.add_argument("--runs", type=cli.folder, default=None,
                        help="folder of training runs (a sweep's output); default: the shipped policies")
    parser.add_argument("--out", type=cli.folder, required=out_default is None, default=out_default,
                        help="output folder" + (f" (default: {out_default})" if out_default else ""))
    parser.add_argument("--quick", action="store_true", help="reduced sizes (minutes on 2 cores)")
    parser.add_argument("--max_per_config", type=cli.integer(1), default=None,
                        help="use at most this many runs per ORC (default: all; 2 with --quick)")
    parser.add_argument("--process_noise", type=cli.number(0.0), default=0.0,
                        help="oscillator process noise [Hz] at evaluation (released scripts: 0.25)")
    parser.add_argument("--seed", type=cli.integer(0), default=0)
    if pushes:
        parser.add_argument("--push_slots", type=cli.integer(1), default=None,
                            help="Table I's push slots per direction (protocol: 50, i.e. 1800 robots per policy "
                                 "and impulse; 4 with --quick); 10 fits seven policies into about a quarter of "
                                 "an hour on 2 cores")
        parser.add_argument("--push_command", type=cli.number(0.0, low_open=True), default=None, metavar="V",
                            help="Table I's forward command [m/s] (default: the protocol's 3, or the highest "
                                 "forward command every policy was trained on if lower)")
    return parser


QUICK_MAX_PER_CONFIG = 2  # --quick without --max_per_config uses this many runs of each configuration


def runs_from_args(args) -> list[PolicyRun]:
    limit = args.max_per_config if args.max_per_config is not None else (QUICK_MAX_PER_CONFIG if args.quick else None)
    return limit_per_config(load_runs(args.runs), limit)


def cli_main(prog: str, description: str, run_fn, argv=None, pushes: bool = False) -> int:
    """`python -m analysis.<module>`: load the runs, call run_fn(runs, out, quick, settings, seed), print paths.

    With `pushes`, --push_slots and --push_command are offered and handed to run_fn as `push_slots` and
    `command`. Errors take learning.cli's
    one error path: one line on stderr, no traceback (unless --debug).
    """
    from learning import cli

    parser = build_parser(prog, description, pushes=pushes)

    def body(args) -> int:
        runs = runs_from_args(args)
        cli.check_writable(args.out)  # before the rollouts, which take minutes
        settings = EvalSettings(process_noise_std=args.process_noise)
        extra = {"push_slots": args.push_slots, "command": args.push_command} if pushes else {}
        summary = run_fn(runs, args.out, quick=args.quick, settings=settings, seed=args.seed, **extra)
        for key, value in summary.get("files", {}).items():
            print(f"{key}: {value}")
        return 0

    return cli.run(parser, body, argv)
