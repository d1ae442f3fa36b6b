"""From what a run asks for to a runner attached to its run folder: one way in for train.py, sweep.py and bench/.

    request = RunRequest(task="mini_cheetah_osc", orc="110", seed=3, max_iterations=600)
    plan = resolve(request)            # every value checked, nothing built or written
    runner, run_dir, lock = start_run(plan)
    runner.learn(plan.train_cfg.max_iterations - runner.current_learning_iteration,
                 plan.train_cfg.init_at_random_ep_len)

`RunRequest` holds train.py's options by their flag names (train.py fills it from its command line; a
program fills it directly), so nothing assembles a command line for the parser.
"""

from __future__ import annotations

import contextlib
import copy
import os
import random
from dataclasses import dataclass, field, fields
from typing import Any

from gym_envs.config import ConfigError

RESUME_LIVE_FIX = "resume it when that process has ended (or stop it first), or choose another run with --load_run"
NEW_FOLDER_FIX = "it is a new folder; nothing else should write it"


@dataclass
class RunRequest:
    """train.py's options, by flag name (None: the default the flag's help describes)."""

    task: str | None = None
    orc: str | None = None
    num_envs: int | None = None
    max_iterations: int | None = None
    seed: int | None = None
    resume: bool = False
    load_run: str | None = None
    checkpoint: int = -1
    experiment_name: str | None = None
    log_root: str | None = None
    run_name: str | None = None
    device: str | None = None
    sim: str | None = None
    num_threads: int | None = None
    profile: str | None = None
    overrides: list[str] = field(default_factory=list)  # --set KEY=VALUE items
    logger: str | None = None
    log_project_name: str | None = None
    video: int | None = None
    video_length: float = 2.0

    @classmethod
    def from_args(cls, args: Any) -> RunRequest:
        return cls(**{f.name: getattr(args, f.name) for f in fields(cls)})


def _cuda_available() -> bool:
    import torch

    return torch.cuda.is_available()


@contextlib.contextmanager
def torch_threads(num_threads: int | None):
    """torch's CPU threads capped at --num_threads while the block runs (0 or None: torch's default), then restored,
    so that a training beside another on the same cores does not run twice as many busy threads as cores."""
    import torch

    before = torch.get_num_threads()
    if num_threads:
        torch.set_num_threads(num_threads)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def seed_everything(seed: int) -> None:
    import numpy as np
    import torch

    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)
    if torch.cuda.is_available():
        torch.cuda.manual_seed_all(seed)


@dataclass
class Plan:
    """What `resolve` decided: configs checked, device chosen, nothing built or written."""

    task: str
    env_cfg: Any  # the task's env config dataclass
    train_cfg: Any  # gym_envs.train_config.TrainCfg
    log_root: str
    rank: int
    world: int
    device: str
    defaults: Any  # learning.machine.RunDefaults
    resume_from: str | None = None
    trained_env_cfg: Any = None  # env config of the run resumed from
    # A resumed run takes its checkpoint's (possibly adapted) learning rate unless this command sets one.
    learning_rate_given: bool = False
    video: tuple[int, float] | None = None  # a clip of robot 0 every N iterations, this many simulated seconds


def resolve(args: RunRequest) -> Plan:
    """The configs of the run args ask for, every value checked; nothing is built or written (under torchrun
    the process joins its group here: a drawn seed is rank 0's)."""
    from gym_envs.registry import env_cfg_class, train_cfg_class
    from gym_envs.orc import parse_training_orc
    from learning import distributed, runs
    from learning.runner_config import (
        apply_split_overrides,
        check_logger_ready,
        derived_experiment_name,
        profile_overrides,
    )
    from learning.machine import choose_defaults, warp_installed

    log_root = args.log_root or runs.default_log_root()
    ranks = distributed.ranks_from_env()
    # The machine's defaults decide cpu or cuda; under torchrun each process takes cuda:<local rank>,
    # and the process group's backend follows (gloo on CPU, NCCL on CUDA).
    defaults = choose_defaults(args.device, args.profile, args.sim, cuda_available=_cuda_available(),
                               warp_available=warp_installed(), resume=args.resume, task=args.task)
    device = distributed.resolve_device(defaults.device, ranks)
    distributed.init_process_group(device, ranks)

    resume_from = trained_env_cfg = None
    if args.resume:
        run_dir = runs.find_run(log_root, args.load_run, experiment=args.experiment_name, task=args.task, orc=args.orc)
        runs.check_not_in_use(run_dir, RESUME_LIVE_FIX)
        resume_from = runs.find_checkpoint(run_dir, args.checkpoint)
        task, env_cfg, train_cfg = runs.load_run_configs(run_dir)
        trained_env_cfg = env_cfg
        if args.task and args.task != task:
            raise ConfigError(f"run {run_dir} trained task {task!r}, not {args.task!r}; drop --task or pick a run")
    else:
        if not args.task:
            raise ConfigError("--task is required (e.g. --task mini_cheetah_osc), unless --resume picks up a run")
        if args.load_run is not None or args.checkpoint != -1:
            raise ConfigError("--load_run and --checkpoint choose what to resume from; add --resume")
        task = args.task
        env_cfg = env_cfg_class(task)()
        train_cfg = train_cfg_class(task)(task=task)

    for item in args.overrides:
        key = item.partition("=")[0].strip()
        if key in ("env.device", "env.seed"):
            raise ConfigError(f"{key} follows --{key[4:]} (and the process rank under torchrun); pass --{key[4:]}")
    env_cfg, train_cfg = apply_split_overrides(env_cfg, train_cfg,
                                               profile_overrides(defaults.profile, task) + args.overrides)
    if args.orc is not None and not hasattr(env_cfg, "osc"):
        raise ConfigError(f"--orc needs a task with oscillators; {task!r} has none")
    flags = {
        "osc.orc": args.orc, "env.num_envs": args.num_envs,
        "sim.backend": defaults.sim, "sim.num_threads": args.num_threads, "train.seed": args.seed,
        "train.experiment_name": args.experiment_name, "train.run_name": args.run_name,
        "train.max_iterations": None if args.resume else args.max_iterations,
        "train.logger": args.logger, "train.log_project_name": args.log_project_name,
    }
    env_cfg, train_cfg = apply_split_overrides(
        env_cfg, train_cfg, [f"{key}={value}" for key, value in flags.items() if value is not None]
    )
    if resume_from is not None:
        start = runs.checkpoint_iteration(resume_from)
        if args.max_iterations is not None:
            train_cfg.max_iterations = start + args.max_iterations
        elif train_cfg.max_iterations <= start:
            raise ConfigError(
                f"checkpoint {resume_from} is at iteration {start}, the run's planned total (train.max_iterations "
                f"{train_cfg.max_iterations}); add --max_iterations N to train N more iterations"
            )
        train_cfg.resumed_from = resume_from
    if defaults.profile:
        train_cfg.profile = defaults.profile
    if train_cfg.seed == -1:
        train_cfg.seed = distributed.shared_random_seed()
    # --orc names the experiment unless one is given; a resumed run keeps its own otherwise.
    if args.experiment_name is None and (not train_cfg.experiment_name or (args.resume and args.orc is not None)):
        train_cfg.experiment_name = derived_experiment_name(task, env_cfg)
    if not train_cfg.run_name:
        train_cfg.run_name = f"seed{train_cfg.seed}"
    if ranks.is_distributed and env_cfg.sim.num_threads == 0:
        env_cfg.sim.num_threads = distributed.thread_share(ranks)
    env_cfg.env.device = device
    env_cfg.env.seed = train_cfg.seed + ranks.rank
    env_cfg.validate()
    train_cfg.validate(env_cfg.env.num_envs)
    if hasattr(env_cfg, "osc"):
        parse_training_orc(env_cfg.osc.orc)
    runs.check_folder_names(train_cfg.experiment_name, train_cfg.run_name)
    check_logger_ready(train_cfg)
    video = None if args.video is None else (args.video, args.video_length)
    learning_rate_given = args.resume and any(item.partition("=")[0].strip() == "train.algorithm.learning_rate" for item in args.overrides)
    return Plan(task, env_cfg, train_cfg, log_root, ranks.rank, ranks.world_size, device, defaults, resume_from,
                trained_env_cfg, learning_rate_given, video)


def start_run(plan: Plan, run_dir: str | None = None, lock_fix: str = NEW_FOLDER_FIX, progress_prefix: str | None = None):
    """Seed, build the env and the runner (loading the checkpoint a resumed plan names), then, on rank 0, make
    the run folder (a new dated one unless `run_dir` is given), hold its lock, write env.yaml and train.yaml
    (unless the folder has them) and attach the runner. Returns (runner, run_dir, lock); on other ranks of a
    torchrun launch run_dir and lock are None."""
    from gym_envs import make_env
    from learning import distributed, runs
    from learning.runner import TaskRunner
    from learning.vec_env import TaskVecEnv

    env_cfg, train_cfg = plan.env_cfg, plan.train_cfg
    seed_everything(train_cfg.seed + plan.rank)
    # The task edits the config it gets (ORC applies itself); the YAML keeps the config as given.
    env = TaskVecEnv(make_env(plan.task, copy.deepcopy(env_cfg)), device=plan.device)
    runner = TaskRunner(env, train_cfg, log_dir=None, device=plan.device)
    if plan.resume_from is not None:
        runner.load(plan.resume_from, context=f"task {plan.task} as configured now",
                    cause=runs.orc_mismatch_cause(plan.trained_env_cfg, env_cfg))
        if train_cfg.max_iterations <= runner.current_learning_iteration:
            raise ConfigError(
                f"checkpoint {plan.resume_from} records iteration {runner.current_learning_iteration}, at or past "
                f"train.max_iterations {train_cfg.max_iterations}; pass --max_iterations N to train N more"
            )
        env.task.continue_from_step(runner.current_learning_iteration * train_cfg.num_steps_per_env)
        if plan.learning_rate_given:  # rsl-rl's load takes the optimizer's rate; the command's wins
            runner.set_learning_rate(train_cfg.algorithm.learning_rate)
    if plan.video is not None and plan.rank == 0:
        from learning.video import TrainingVideo

        runner.video = TrainingVideo(env.task.sim, env.task.dt, *plan.video)
    distributed.barrier()  # every rank has read the run it resumes before rank 0 adds a folder
    if plan.rank != 0:
        return runner, None, None
    if run_dir is None:
        if plan.resume_from:
            runs.remove_stale_temps_of_idle_run(os.path.dirname(plan.resume_from), RESUME_LIVE_FIX)
        run_dir = runs.create_run_dir(plan.log_root, train_cfg.experiment_name, train_cfg.run_name)
    os.makedirs(run_dir, exist_ok=True)
    lock = runs.FolderLock(run_dir, lock_fix)
    resumed_in_place = plan.resume_from is not None and os.path.samefile(os.path.dirname(plan.resume_from), run_dir)
    if not resumed_in_place:  # a run continued in its own folder keeps the configs it has
        runs.save_run_configs(run_dir, env_cfg, train_cfg)
    runner.attach_run_dir(run_dir, progress_prefix or f"[{train_cfg.experiment_name}] ")
    return runner, run_dir, lock
