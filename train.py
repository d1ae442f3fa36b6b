"""Train a gym_envs task with rsl-rl-lib PPO.

    python train.py --task mini_cheetah_osc --orc 110 --seed 3
    python train.py --task mini_cheetah_osc --profile cpu_fast --set train.algorithm.learning_rate=3e-4
    python train.py --resume                      # newest run, its newest checkpoint, up to train.max_iterations
    python train.py --resume --load_run 2025-01-01_12-00-00_seed3 --checkpoint 500 --max_iterations 3000

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
modified, and the new one records `resumed_from`. The env and train configs are the old run's
YAMLs, changed by any options given now. The iteration count continues (the next iteration after
model_500.pt is number 501, its tensorboard step 500), so the two folders' curves join up when
tensorboard shows the experiment folder. --max_iterations is the total to reach, not a count to add.

Seeds. --seed (default 0; -1 draws one) seeds python, numpy and torch, and becomes env.seed;
train.yaml and env.yaml record the values used.

Ctrl-C stops at the next env step and saves model_<completed iterations>.pt (exit status 130);
a second Ctrl-C aborts without saving. Errors in the inputs print one line and exit with status 1
before anything is written.

Devices. --device cpu|cuda puts the task's tensors and the learner there; the 'mujoco' physics
always runs on CPU threads (--num_threads, which also caps torch's CPU threads).

Several processes (data-parallel PPO: gradients, KL and observation statistics averaged over
ranks) start under torchrun, on CPU processes (gloo) or one GPU each (NCCL, cuda:<LOCAL_RANK>):

    torchrun --standalone --nproc_per_node=2 train.py --task mini_cheetah_osc --num_threads 1
    torchrun --standalone --nproc_per_node=4 train.py --task mini_cheetah_osc --device cuda --sim warp

Each process simulates --num_envs robots with seed + RANK; --num_threads 0 (the default) gives
each process's physics its share of the cores (torch keeps torchrun's OMP_NUM_THREADS, 1). Only
rank 0 writes the run folder and prints progress; Ctrl-C reaches every rank, and rank 0 saves
before all exit.
"""

from __future__ import annotations

import argparse
import copy
import os
import random
import sys
from dataclasses import dataclass
from typing import Any

from gym_envs.config import ConfigError

EXIT_INTERRUPTED = 130


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="train.py", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--task", help="task name (mini_cheetah_osc, mini_cheetah); with --resume, defaults to the run's")
    p.add_argument("--orc", help="ORC string for oscillator tasks (sets osc.orc; experiment ORC_<orc> by default)")
    p.add_argument("--num_envs", type=int, help="robots (per process under torchrun)")
    p.add_argument("--max_iterations", type=int, help="total PPO iterations of the run (a resumed run continues to it)")
    p.add_argument("--seed", type=int, help="seed of python/numpy/torch and env.seed (-1: draw one); default 0")
    p.add_argument("--headless", action="store_true", help="accepted for compatibility; training never renders")
    p.add_argument("--resume", action="store_true", help="continue from a checkpoint (newest run unless --load_run)")
    p.add_argument("--load_run", help="run to resume: a folder name in the experiment, or a path")
    p.add_argument("--checkpoint", type=int, default=-1, help="iteration to resume from (-1: the newest)")
    p.add_argument("--experiment_name", help="experiment folder under the log root")
    p.add_argument("--run_name", help="suffix of the run folder name (default seed<seed>)")
    p.add_argument("--device", choices=("cpu", "cuda"), help="task tensors and learner (default cpu)")
    p.add_argument("--sim", choices=("mujoco", "warp"), help="physics backend (sets sim.backend)")
    p.add_argument("--num_threads", type=int, help="CPU threads of the physics and of torch (0: all cores)")
    p.add_argument("--profile", help="named override set from learning.runner_config.PROFILES (paper, cpu_fast)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="config override, repeatable: train.<key> for the train config, other keys for the env config")
    p.add_argument("--log_root", help="folder of experiments (default: $ORCGYM_LOG_ROOT or <repo>/logs)")
    return p


def seed_everything(seed: int) -> None:
    import numpy as np
    import torch

    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)
    if torch.cuda.is_available():
        torch.cuda.manual_seed_all(seed)


def prepare(args: argparse.Namespace):
    """Configs, env and runner, checked and built; nothing is written yet."""
    from gym_envs import env_cfg_class, make_env
    from gym_envs.orc import parse_orc
    from learning import distributed, runs
    from learning.runner import TaskRunner
    from learning.runner_config import (
        apply_split_overrides,
        derived_experiment_name,
        profile_overrides,
        train_cfg_class,
    )
    from learning.vec_env import TaskVecEnv

    log_root = args.log_root or runs.default_log_root()
    ranks = distributed.ranks_from_env()
    device = distributed.resolve_device(args.device, ranks)
    distributed.init_process_group(device, ranks)

    resume_from = None
    if args.resume:
        run_dir = runs.find_run(log_root, args.load_run, experiment=args.experiment_name, task=args.task, orc=args.orc)
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

    env_cfg, train_cfg = apply_split_overrides(env_cfg, train_cfg, profile_overrides(args.profile) + args.overrides)
    if args.orc is not None and not hasattr(env_cfg, "osc"):
        raise ConfigError(f"--orc needs a task with oscillators; {task!r} has none")
    flags = {
        "osc.orc": args.orc, "env.num_envs": args.num_envs,
        "sim.backend": args.sim, "sim.num_threads": args.num_threads,
        "train.max_iterations": args.max_iterations, "train.seed": args.seed,
        "train.experiment_name": args.experiment_name, "train.run_name": args.run_name,
    }
    env_cfg, train_cfg = apply_split_overrides(
        env_cfg, train_cfg, [f"{key}={value}" for key, value in flags.items() if value is not None]
    )
    if hasattr(env_cfg, "osc"):
        parse_orc(env_cfg.osc.orc)
    if args.profile:
        train_cfg.profile = args.profile
    if train_cfg.seed == -1:
        train_cfg.seed = distributed.shared_random_seed()
    # --orc names the experiment unless one is given; a resumed run keeps its own otherwise.
    if args.experiment_name is None and (not train_cfg.experiment_name or (args.resume and args.orc is not None)):
        train_cfg.experiment_name = derived_experiment_name(task, env_cfg)
    if not train_cfg.run_name:
        train_cfg.run_name = f"seed{train_cfg.seed}"
    runs.check_folder_names(train_cfg.experiment_name, train_cfg.run_name)
    if ranks.is_distributed and env_cfg.sim.num_threads == 0:
        env_cfg.sim.num_threads = distributed.thread_share(ranks)
    env_cfg.env.device = device
    env_cfg.env.seed = train_cfg.seed + ranks.rank
    if resume_from is not None:
        train_cfg.resumed_from = resume_from

    seed_everything(train_cfg.seed + ranks.rank)
    # The task edits the config it gets (ORC applies itself); the YAML keeps the config as given.
    env = TaskVecEnv(make_env(task, copy.deepcopy(env_cfg)), device=device)
    runner = TaskRunner(env, train_cfg, log_dir=None, device=device)
    if resume_from is not None:
        runner.load(resume_from, context=f"task {task} as configured now",
                    cause=runs.orc_mismatch_cause(trained_env_cfg, env_cfg))
        if train_cfg.max_iterations <= runner.current_learning_iteration:
            raise ConfigError(
                f"checkpoint {resume_from} is at iteration {runner.current_learning_iteration} and max_iterations is "
                f"{train_cfg.max_iterations}; pass a larger --max_iterations"
            )
    return Setup(task, env_cfg, train_cfg, runner, log_root, ranks.rank)


@dataclass
class Setup:
    """What `prepare` built: everything checked, nothing written."""

    task: str
    env_cfg: Any  # the task's env config dataclass
    train_cfg: Any  # learning.runner_config.TrainCfg
    runner: Any  # learning.runner.TaskRunner
    log_root: str
    rank: int


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    import torch

    from gym_envs.config import save_yaml
    from gym_envs.sim import SimSetupError
    from learning import distributed, runs
    from learning.runner import StopRequest

    threads_before = torch.get_num_threads()
    try:
        if args.num_threads:
            torch.set_num_threads(args.num_threads)
        try:
            setup = prepare(args)
        except (ConfigError, SimSetupError) as err:
            print(f"train.py: error: {runs.one_line(err)}", file=sys.stderr)
            return 1
        env_cfg, train_cfg, runner = setup.env_cfg, setup.train_cfg, setup.runner
        distributed.barrier()  # every rank has read the runs it resumes before rank 0 adds a folder
        if setup.rank == 0:
            run_dir = runs.create_run_dir(setup.log_root, train_cfg.experiment_name, train_cfg.run_name)
            save_yaml(env_cfg, os.path.join(run_dir, runs.ENV_YAML))
            save_yaml(train_cfg, os.path.join(run_dir, runs.TRAIN_YAML))
            runner.attach_run_dir(run_dir, progress_prefix=f"[{train_cfg.experiment_name}] ")
            resuming = f" (resuming {train_cfg.resumed_from})" if train_cfg.resumed_from else ""
            print(f"task {setup.task} | {env_cfg.env.num_envs} envs on {env_cfg.env.device} | {runner.describe()}")
            print(f"run folder {run_dir}{resuming}", flush=True)

        with StopRequest(announce=setup.rank == 0) as stop:
            finished = runner.train(train_cfg.max_iterations, train_cfg.init_at_random_ep_len, stop)
        if finished:
            return 0
        if setup.rank == 0:
            saved = runs.checkpoint_path(runner.log_dir, runner.current_learning_iteration)
            print(f"stopped at iteration {runner.current_learning_iteration}; saved {saved}", flush=True)
        return EXIT_INTERRUPTED
    finally:
        torch.set_num_threads(threads_before)
        distributed.shut_down()


if __name__ == "__main__":
    sys.exit(main())
