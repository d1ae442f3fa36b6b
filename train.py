"""Train a gym_envs task with rsl-rl-lib PPO.

    python train.py --task mini_cheetah_osc --orc 110 --seed 3
    python train.py --task mini_cheetah_osc --profile cpu_fast --set train.algorithm.learning_rate=3e-4
    python train.py --resume                      # newest run, its newest checkpoint, on to its planned total
    python train.py --resume --load_run 2025-01-01_12-00-00_seed3 --checkpoint 500 --max_iterations 1000
    python train.py --task mini_cheetah_osc --profile cpu_fast --print_config   # the resolved configs as YAML

Configs. The task's defaults (gym_envs env config + learning.runner_config train config) are
changed, in this order, by --profile, by each --set KEY=VALUE, and last by the dedicated options
(--orc, --num_envs, --seed, ...). KEY `train.<path>` sets the train config
(train.algorithm.learning_rate=1e-4, train.num_steps_per_env=24); any other KEY sets the env
config (env.num_envs=512, osc.orc=110, rewards.weights.torques=0, sim.num_threads=2). Unknown keys
are errors with a did-you-mean hint.

Runs. Each run gets a new folder <log_root>/<experiment>/<YYYY-mm-dd_HH-MM-SS>_<run>/ holding
env.yaml, train.yaml (task, seed, profile, everything), model_<it>.pt checkpoints (it = completed
iterations; model_0 is the initial policy) and tensorboard events. The experiment defaults to
ORC_<orc> for oscillator tasks (else the task name) and the run name to seed<seed>.

Resuming (--resume) loads a checkpoint and writes a *new* run folder: the old run is never
modified (beyond removing the temporary file of a save that was killed), and the new one records
`resumed_from`. A run that is still being written (its process holds <run>/.lock) is not resumed:
the error names that process. The env and train configs are the old run's
YAMLs, changed by any options given now. The iteration count continues (the next iteration after
model_500.pt is number 501, its tensorboard step 500), so the two folders' curves join up when
tensorboard shows the experiment folder.

Iterations. --max_iterations is the number of PPO iterations this command runs, as in legged_gym:
a new run's total, and on --resume the iterations *added* to the checkpoint's (resuming
model_500.pt with --max_iterations 1000 ends at model_1500.pt; a finished run continues the same
way). --resume without it continues to the run's planned total (train.max_iterations, which
train.yaml always records as a total) and says so when the run has already reached it.

Seeds. --seed (default 0; -1 draws one) seeds python, numpy and torch, and becomes env.seed;
train.yaml and env.yaml record the values used.

Ctrl-C or SIGTERM (a cluster scheduler's stop) ends training at the next env step and saves
model_<completed iterations>.pt (exit status 130 or 143; under torchrun every rank stops at the
same iteration); a second one aborts without saving. Every flag and config value is checked before anything is
built or written; a bad one is one line on stderr naming it and what is allowed (exit status 1;
2 for a malformed flag). --debug shows the traceback of any error.

Defaults that fit the machine (learning/machine.py). Without --device the run uses CUDA when torch
sees a device, else the CPU; without --profile it trains the paper's settings on CUDA and a CPU recipe
on the CPU ({cpu_recipes}; under cpu_oscillators ORC-111 follows its oscillators); without --sim it simulates with
MuJoCo Warp on CUDA when the gpu extra is installed. The first lines of a run say what was chosen,
why, the expected duration (for the CPU, from the rate measured on a 2-core machine) and the flag
that picks the other settings. A resumed run keeps its own profile and physics.

Monitoring. --logger wandb|neptune (project --log_project_name) adds rsl-rl-lib's W&B or Neptune
writer to the tensorboard events (extras: pip install -e ".[wandb]" / ".[neptune]"; W&B offline:
WANDB_MODE=offline). --video N records --video_length seconds of robot 0 every N iterations into
<run>/videos/iter_<it>.mp4, offscreen (MUJOCO_GL=egl without a display, osmesa as the fallback),
and W&B receives each clip.

Devices. --device cpu|cuda puts the task's tensors and the learner there; the 'mujoco' physics
always runs on CPU threads (--num_threads, which also caps torch's CPU threads).

Several processes (data-parallel PPO: gradients, KL and observation statistics averaged over
ranks) start under torchrun, on CPU processes (gloo) or one GPU each (NCCL, cuda:<LOCAL_RANK>); the
device is chosen as for one process (without --device: CUDA when torch sees it, else the CPU):

    torchrun --standalone --nproc_per_node=2 train.py --task mini_cheetah_osc --num_threads 1
    torchrun --standalone --nproc_per_node=4 train.py --task mini_cheetah_osc --device cuda --sim warp

Each process simulates --num_envs robots with seed + RANK; --num_threads 0 (the default) gives
each process's physics its share of the cores (torch keeps torchrun's OMP_NUM_THREADS, 1). Only
rank 0 writes the run folder and prints progress; Ctrl-C reaches every rank, and rank 0 saves
before all exit.
"""

from __future__ import annotations

from learning.startup import quiet_ctrl_c_at_startup

quiet_ctrl_c_at_startup()  # before the slow imports below

import argparse  # noqa: E402
import copy  # noqa: E402
import os  # noqa: E402
import random  # noqa: E402
import sys  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from typing import Any  # noqa: E402

from gym_envs.config import ConfigError  # noqa: E402
from learning import cli, machine  # noqa: E402

RESUME_LIVE_FIX = "resume it when that process has ended (or stop it first), or choose another run with --load_run"


def build_parser() -> cli.Parser:
    p = cli.Parser("train.py", __doc__.replace("{cpu_recipes}", machine.cpu_recipes_text()))
    p.add_argument("--task", help="task name (mini_cheetah_osc, mini_cheetah); with --resume, defaults to the run's")
    p.add_argument("--orc", type=cli.orc, help="ORC string for oscillator tasks (sets osc.orc; experiment ORC_<orc>)")
    p.add_argument("--num_envs", type=cli.integer(1), help="robots (per process under torchrun)")
    p.add_argument("--max_iterations", type=cli.integer(1),
                   help="PPO iterations to run: a new run's total; with --resume, iterations added to the "
                        "checkpoint's (default: train.max_iterations; --resume: on to the run's planned total)")
    p.add_argument("--seed", type=cli.integer(-1), help="seed of python/numpy/torch and env.seed (-1: draw one); "
                   "default 0")
    p.add_argument("--headless", action="store_true", help="accepted as in legged_gym: training opens no window (--video renders offscreen)")
    p.add_argument("--resume", action="store_true", help="continue from a checkpoint (newest run unless --load_run)")
    cli.add_run_selection(p, "resume")
    p.add_argument("--run_name", type=cli.name, help="suffix of the run folder name (default seed<seed>)")
    cli.add_compute(p)
    p.add_argument("--profile", help="named override set from learning.runner_config.PROFILES: paper, cpu_fast, "
                   "cpu_oscillators (default: paper on cuda; on cpu cpu_oscillators for mini_cheetah_osc, else "
                   "cpu_fast; a resumed run keeps its own)")
    cli.add_overrides(p, "config override, repeatable: train.<key> for the train config, other keys for the env "
                         "config")
    p.add_argument("--logger", choices=("tensorboard", "wandb", "neptune"),
                   help="where metrics go besides the run folder's tensorboard events (default tensorboard); "
                   "wandb and neptune need their extra: pip install -e \".[wandb]\" / \".[neptune]\"")
    p.add_argument("--log_project_name", help="W&B or Neptune project (default orcgym)")
    p.add_argument("--video", type=cli.integer(1), metavar="N", help="every N iterations, record a clip of robot 0 "
                   "into <run>/videos/iter_<it>.mp4 (uploaded to W&B with --logger wandb; offscreen, MUJOCO_GL=egl)")
    p.add_argument("--video_length", type=cli.number(0.0, low_open=True), default=2.0, metavar="SECONDS",
                   help="simulated seconds per --video clip (default 2)")
    cli.add_print_config(p)
    return p


def _cuda_available() -> bool:
    import torch

    return torch.cuda.is_available()


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
    train_cfg: Any  # learning.runner_config.TrainCfg
    log_root: str
    rank: int
    world: int
    device: str
    defaults: Any  # learning.machine.RunDefaults
    resume_from: str | None = None
    trained_env_cfg: Any = None  # env config of the run resumed from


def resolve(args: argparse.Namespace) -> Plan:
    """The configs of the run args ask for, every value checked; nothing is built or written (under torchrun
    the process joins its group here: a drawn seed is rank 0's)."""
    from gym_envs import env_cfg_class
    from gym_envs.orc import parse_training_orc
    from learning import distributed, runs
    from learning.runner_config import (
        apply_split_overrides,
        check_logger_ready,
        derived_experiment_name,
        profile_overrides,
        train_cfg_class,
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
        train_cfg = train_cfg_class(task)()

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
    return Plan(task, env_cfg, train_cfg, log_root, ranks.rank, ranks.world_size, device, defaults, resume_from,
                trained_env_cfg)


def build(plan: Plan) -> Setup:
    """Seed, then build the env and the runner (and load the checkpoint to resume from); nothing is written."""
    from gym_envs import make_env
    from learning import runs
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
    return Setup(plan.task, env_cfg, train_cfg, runner, plan.log_root, plan.rank, plan.world, plan.defaults)


def prepare(args: argparse.Namespace) -> Setup:
    """Configs, env and runner, checked and built; nothing is written yet."""
    return build(resolve(args))


@dataclass
class Setup:
    """What `prepare` built: everything checked, nothing written."""

    task: str
    env_cfg: Any  # the task's env config dataclass
    train_cfg: Any  # learning.runner_config.TrainCfg
    runner: Any  # learning.runner.TaskRunner
    log_root: str
    rank: int
    world: int
    defaults: Any  # learning.machine.RunDefaults: what was chosen for the flags left open, and why


def main(argv: list[str] | None = None) -> int:
    return cli.run(build_parser(), _main, argv)


def _main(args: argparse.Namespace) -> int:
    import torch

    from learning import distributed, runs
    from learning.machine import expected_duration
    from learning.runner import StopRequest

    if args.video is not None:
        from learning.video import prefer_offscreen_gl

        prefer_offscreen_gl()  # before mujoco is imported
    threads_before = torch.get_num_threads()
    lock = None
    try:
        if args.num_threads:
            torch.set_num_threads(args.num_threads)
        plan = resolve(args)
        if args.print_config:
            print(cli.config_yaml(plan.env_cfg, plan.train_cfg), end="")
            return 0
        setup = build(plan)
        if args.video is not None and setup.rank == 0:
            from learning.video import TrainingVideo

            task = setup.runner.env.task
            setup.runner.video = TrainingVideo(task.sim, task.dt, args.video, args.video_length)
        env_cfg, train_cfg, runner = setup.env_cfg, setup.train_cfg, setup.runner
        distributed.barrier()  # every rank has read the runs it resumes before rank 0 adds a folder
        if setup.rank == 0:
            if plan.resume_from:
                runs.remove_stale_temps_of_idle_run(os.path.dirname(plan.resume_from), RESUME_LIVE_FIX)
            run_dir = runs.create_run_dir(setup.log_root, train_cfg.experiment_name, train_cfg.run_name)
            lock = runs.FolderLock(run_dir, "it is a new folder; nothing else should write it")
            runs.save_run_configs(run_dir, env_cfg, train_cfg)
            runner.attach_run_dir(run_dir, progress_prefix=f"[{train_cfg.experiment_name}] ")
            resuming = f" (resuming {train_cfg.resumed_from})" if train_cfg.resumed_from else ""
            print(setup.defaults.describe(env_cfg.sim.backend))
            print(expected_duration(env_cfg.env.device.split(":")[0], env_cfg.sim.backend, env_cfg.env.num_envs,
                                    train_cfg.num_steps_per_env,
                                    train_cfg.max_iterations - runner.current_learning_iteration, setup.world,
                                    mirrored=train_cfg.algorithm.symmetry_cfg.use_data_augmentation))
            print(f"task {setup.task} | {env_cfg.env.num_envs} envs on {env_cfg.env.device} | {runner.describe()}")
            print(f"run folder {run_dir}{resuming}", flush=True)

        with StopRequest(announce=setup.rank == 0) as stop:
            finished = runner.learn(train_cfg.max_iterations - runner.current_learning_iteration,
                                    train_cfg.init_at_random_ep_len, stop)
        if finished:
            return 0
        if setup.rank == 0:
            saved = runs.checkpoint_path(runner.log_dir, runner.current_learning_iteration)
            print(f"stopped at iteration {runner.current_learning_iteration}; saved {saved}", flush=True)
        return stop.exit_status
    finally:
        if lock is not None:
            lock.release()
        torch.set_num_threads(threads_before)
        distributed.shut_down()


if __name__ == "__main__":
    sys.exit(main())
