"""Train every ORC configuration of the paper for several seeds: the ablation's training campaign.

    python sweep.py --seeds 0 1 2 --out logs/sweep   # the CPU recipe cpu_envelope (--profile to choose)
    python sweep.py --orcs 111 110 --seeds 0 --set train.algorithm.learning_rate=1e-4

Each run has a fixed folder <out>/ORC_<xyz>/seed<k>/ (env.yaml, train.yaml, model_<it>.pt,
tensorboard events), so calling the same command again skips finished runs and resumes an
interrupted one in place from its newest checkpoint (its configs must match the command's).
<out>/manifest.csv lists configuration, seed, iterations, wall time, final reward and final
tracking error (mean |command - velocity| of the last episodes) of every run; it is rewritten
after each run. Ctrl-C or SIGTERM stops the current run with a checkpoint and ends the sweep (exit 130 or 143).
Every run's flags and config values are checked before the first folder is made. A sweep holds a
lock on <out> (and on the run it trains) until it ends: a second sweep into the same <out>, or a
train.py --resume of the run being trained, is refused with the sweep's pid.
"""

from __future__ import annotations

from learning.startup import quiet_ctrl_c_at_startup

quiet_ctrl_c_at_startup()  # before the slow imports below

import csv  # noqa: E402
import glob  # noqa: E402
import os  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import yaml  # noqa: E402

from gym_envs.config import ConfigError, apply_overrides, to_dict  # noqa: E402
from gym_envs.files import atomic_write  # noqa: E402
from gym_envs.orc import PAPER_CONFIGURATIONS  # noqa: E402
from learning import cli, launch, runs  # noqa: E402
from learning.runner import StopRequest  # noqa: E402

MANIFEST = "manifest.csv"
STATUS = "sweep_status.yaml"
FIELDS = ("orc", "seed", "iterations", "wall_time_s", "final_reward", "tracking_error", "run_dir")


def build_parser() -> cli.Parser:
    parser = cli.Parser("sweep.py", __doc__)
    parser.add_argument("--out", type=cli.folder, default=os.path.join(runs.default_log_root(), "sweep"),
                        help="sweep folder")
    parser.add_argument("--orcs", nargs="+", type=cli.orc, default=list(PAPER_CONFIGURATIONS),
                        help="ORC strings (default: the 7 of the paper)")
    parser.add_argument("--seeds", nargs="+", type=cli.integer(0), default=[0])
    parser.add_argument("--max_iterations", type=cli.integer(1), default=None,
                        help="total PPO iterations per run (default: the train config's)")
    parser.add_argument("--num_envs", type=cli.integer(1), default=None)
    parser.add_argument("--profile", default=None, help="as in train.py (default: cpu_envelope on cpu, paper on cuda)")
    cli.add_compute(parser)
    cli.add_overrides(parser, "config override for every run, as in train.py")
    return parser


def run_request(args, orc: str, seed: int) -> launch.RunRequest:
    """What one run of the sweep asks for, as train.py's options would."""
    return launch.RunRequest(
        task="mini_cheetah_osc", orc=orc, seed=seed, log_root=args.out, experiment_name=f"ORC_{orc}",
        run_name=f"seed{seed}", overrides=list(args.overrides),
        **{flag: getattr(args, flag) for flag in ("max_iterations", "num_envs", "profile", "num_threads", "device", "sim")},
    )


def run_dir_of(out: str, orc: str, seed: int) -> str:
    return os.path.join(out, f"ORC_{orc}", f"seed{seed}")


def train_one(args, orc: str, seed: int, stop: StopRequest) -> str:
    """Train, resume or skip one run; returns 'finished', 'skipped' or 'stopped' (by `stop`)."""
    run_dir = run_dir_of(args.out, orc, seed)
    plan = launch.resolve(run_request(args, orc, seed))
    env_cfg, train_cfg = plan.env_cfg, plan.train_cfg
    done = runs.list_checkpoints(run_dir) if os.path.isdir(run_dir) else []
    if done:
        _check_same_configs(run_dir, env_cfg, train_cfg)
        if max(done) >= train_cfg.max_iterations:
            return "skipped"  # read only: a finished run is left exactly as it is
        plan.resume_from, plan.trained_env_cfg = runs.checkpoint_path(run_dir, max(done)), env_cfg
    # The lock is held while the run is written, so that train.py --resume of it is refused (the sweep's own lock
    # on --out keeps other sweeps out).
    runner, _, lock = launch.start_run(plan, run_dir, progress_prefix=f"[ORC_{orc} seed{seed}] ",
                                       lock_fix="resume it with this sweep when that process has ended, or choose "
                                                "another --out")
    with lock:
        status = load_yaml_dict(os.path.join(run_dir, STATUS))
        print(f"resuming {run_dir} from iteration {max(done)}" if done else f"training {run_dir}", flush=True)
        start = time.perf_counter()
        finished = runner.learn(train_cfg.max_iterations - runner.current_learning_iteration,
                                train_cfg.init_at_random_ep_len, stop)
        logger = runner.logger
        status = {
            "orc": orc,
            "seed": seed,
            "iterations": runner.current_learning_iteration,
            "wall_time_s": round(float(status.get("wall_time_s", 0.0)) + time.perf_counter() - start, 1),
            "final_reward": logger.last_reward if logger.last_reward is not None else status.get("final_reward"),
            "tracking_error": (logger.last_tracking_error if logger.last_tracking_error is not None
                               else status.get("tracking_error")),
        }
        save_status(status, os.path.join(run_dir, STATUS))
        return "finished" if finished else "stopped"


def _check_same_configs(run_dir: str, env_cfg, train_cfg) -> None:
    """A run is only continued with the settings it was started with (iterations and physics threads aside)."""
    saved_env = to_dict(runs.load_run_yaml(run_dir, type(env_cfg), runs.ENV_YAML))
    saved_train = runs.load_run_yaml(run_dir, type(train_cfg), runs.TRAIN_YAML)
    saved_train = to_dict(apply_overrides(saved_train, [f"max_iterations={train_cfg.max_iterations}"]))
    # How many cores step the physics is the machine's, not the experiment's: a run may continue on another one.
    saved_env["sim"]["num_threads"] = env_cfg.sim.num_threads
    for name, saved, now in (("env", saved_env, to_dict(env_cfg)), ("train", saved_train, to_dict(train_cfg))):
        if saved != now:
            key = _first_difference(saved, now)
            raise ConfigError(f"{run_dir} was started with other {name} settings ({key} differs); "
                              f"repeat its original options or choose another --out")


def _first_difference(a, b, path: str = "") -> str:
    if isinstance(a, dict) and isinstance(b, dict):
        for key in list(a) + [k for k in b if k not in a]:
            if a.get(key) != b.get(key):
                return _first_difference(a.get(key), b.get(key), f"{path}.{key}" if path else str(key))
    return path


def load_yaml_dict(path: str) -> dict:
    if not os.path.isfile(path):
        return {}
    with open(path) as f:
        return yaml.safe_load(f) or {}


def save_status(status: dict, path: str) -> None:
    with atomic_write(path) as f:
        yaml.safe_dump(status, f, sort_keys=False)


def write_manifest(out: str) -> str:
    """manifest.csv of every run under out (all configurations and seeds any invocation trained)."""
    rows = []
    for status_path in sorted(glob.glob(os.path.join(out, "ORC_*", "seed*", STATUS))):
        status = load_yaml_dict(status_path)
        run_dir = os.path.dirname(status_path)
        rows.append({**{k: status.get(k, "") for k in FIELDS}, "run_dir": os.path.relpath(run_dir, out)})
    path = os.path.join(out, MANIFEST)
    with atomic_write(path) as f:
        writer = csv.DictWriter(f, fieldnames=FIELDS)
        writer.writeheader()
        writer.writerows(rows)
    return path


def main(argv: list[str] | None = None) -> int:
    return cli.run(build_parser(), _main, argv)


# Keys each run of the sweep sets itself (from --orcs, --seeds and its folder layout).
SWEEP_KEYS = ("osc.orc", "train.seed", "train.experiment_name", "train.run_name")


def _main(args) -> int:
    for item in args.overrides:
        if item.partition("=")[0].strip() in SWEEP_KEYS:
            raise ConfigError(f"--set {item}: the sweep sets {', '.join(SWEEP_KEYS)} for each run (--orcs, --seeds)")
    # Every run's configs are checked before the first folder is made.
    for orc in args.orcs:
        for seed in args.seeds:
            launch.resolve(run_request(args, orc, seed))
    os.makedirs(args.out, exist_ok=True)
    with runs.FolderLock(args.out, "wait for that sweep to end (or stop it), or choose another --out"), \
            StopRequest() as stop, launch.torch_threads(args.num_threads):
        for orc in args.orcs:
            for seed in args.seeds:
                outcome = "stopped" if stop.requested else train_one(args, orc, seed, stop)
                print(f"ORC {orc} seed {seed}: {outcome}", flush=True)
                write_manifest(args.out)
                if outcome == "stopped":
                    return stop.exit_status
        print(f"manifest: {write_manifest(args.out)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
