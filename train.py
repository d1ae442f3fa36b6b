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
on the CPU ({cpu_recipes}; under cpu_envelope ORC-111 follows its oscillators and its commands); without --sim it simulates with
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
import sys  # noqa: E402

from learning import cli, machine  # noqa: E402


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
                   "cpu_oscillators, cpu_envelope (default: paper on cuda; on cpu cpu_envelope for mini_cheetah_osc, "
                   "else cpu_fast; a resumed run keeps its own)")
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


def main(argv: list[str] | None = None) -> int:
    return cli.run(build_parser(), _main, argv)


def _main(args: argparse.Namespace) -> int:
    from learning import distributed, launch, runs
    from learning.machine import expected_duration
    from learning.runner import StopRequest

    if args.video is not None:
        from learning.video import prefer_offscreen_gl

        prefer_offscreen_gl()  # before mujoco is imported
    with launch.torch_threads(args.num_threads):
        lock = None
        try:
            plan = launch.resolve(launch.RunRequest.from_args(args))
            if args.print_config:
                print(cli.config_yaml(plan.env_cfg, plan.train_cfg), end="")
                return 0
            runner, run_dir, lock = launch.start_run(plan)
            env_cfg, train_cfg = plan.env_cfg, plan.train_cfg
            if plan.rank == 0:
                resuming = f" (resuming {train_cfg.resumed_from})" if train_cfg.resumed_from else ""
                print(plan.defaults.describe(env_cfg.sim.backend))
                print(expected_duration(env_cfg.env.device.split(":")[0], env_cfg.sim.backend, env_cfg.env.num_envs,
                                        train_cfg.num_steps_per_env,
                                        train_cfg.max_iterations - runner.current_learning_iteration, plan.world,
                                        mirrored=train_cfg.algorithm.symmetry_cfg.use_data_augmentation,
                                        hidden_dims=train_cfg.actor.hidden_dims))
                print(f"task {plan.task} | {env_cfg.env.num_envs} envs on {env_cfg.env.device} | {runner.describe()}")
                for start_step, changes in env_cfg.second_stages():
                    print(f"second stage from iteration {-(-start_step // train_cfg.num_steps_per_env)}: {changes}")
                print(f"run folder {run_dir}{resuming}", flush=True)

            with StopRequest(announce=plan.rank == 0) as stop:
                finished = runner.learn(train_cfg.max_iterations - runner.current_learning_iteration,
                                        train_cfg.init_at_random_ep_len, stop)
            if finished:
                return 0
            if plan.rank == 0:
                saved = runs.checkpoint_path(run_dir, runner.current_learning_iteration)
                print(f"stopped at iteration {runner.current_learning_iteration}; saved {saved}", flush=True)
            return stop.exit_status
        finally:
            if lock is not None:
                lock.release()
            distributed.shut_down()


if __name__ == "__main__":
    sys.exit(main())
