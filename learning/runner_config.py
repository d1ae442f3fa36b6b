"""The rsl-rl-lib 5.x dict form of a train config (gym_envs.train_config), named profiles, and overrides.

A train config is a dataclass tree like the env configs of gym_envs, so the same tools apply:
`gym_envs.config.apply_overrides`, `save_yaml` and `load_yaml` (every run folder keeps a
`train.yaml`). `to_rsl_rl_dict` turns it into the plain dict `rsl_rl.runners.OnPolicyRunner` takes.

Overrides address two trees with one syntax (`split_overrides`):
  * `train.<key>=<value>` goes to the train config, e.g. `train.algorithm.learning_rate=1e-4`;
  * every other key goes to the env config, e.g. `env.num_envs=512` or `osc.orc=110`.
Profiles (`PROFILES`) are named lists of such overrides, applied on top of the task defaults.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from gym_envs.config import ConfigError, apply_overrides, to_dict
from gym_envs.train_config import LOGGERS, TRAIN_PREFIX, TrainCfg


# --- profiles ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Profile:
    description: str
    overrides: tuple[str, ...] = ()  # same scheme as --set: 'train.'-prefixed keys are train keys
    tasks: tuple[str, ...] = ()  # the tasks it applies to; empty: every task


PROFILES: dict[str, Profile] = {
    "paper": Profile(
        "the released ORCAgym setup (4096 envs x 32 steps, 2000 iterations, lr 1e-5 adaptive); "
        "these are the task defaults, so the profile changes nothing"
    ),
    # Tuned for wall-clock on 2 CPU cores (bench/time_to_obedience.py): a quarter of the robots, shorter
    # rollouts, a smaller network (the PPO update is a third of each iteration on a CPU), a larger
    # starting learning rate under the same adaptive-KL schedule, GAE lambda 0.95, less entropy, and
    # commands concentrated on forward walking (v_x from {0, 1, 2} m/s + N(0, 0.3^2)).
    "cpu_fast": Profile(
        "fast wall-clock learning on a 2-core CPU: 1024 envs x 24 steps, 300 iterations, [128, 128, 64] networks, "
        "lr 1e-3 adaptive, lambda 0.95, forward-walking commands",
        (
            "env.num_envs=1024",
            "train.max_iterations=300",
            "commands.lin_vel_x_choices=[0.0, 1.0, 2.0]",
            "commands.lin_vel_x_noise=0.3",
            "commands.lin_vel_y=[-0.3, 0.3]",
            "commands.yaw_rate=[-1.0, 1.0]",
            "train.num_steps_per_env=24",
            "train.algorithm.learning_rate=1e-3",
            "train.algorithm.num_learning_epochs=4",
            "train.algorithm.num_mini_batches=4",
            "train.algorithm.lam=0.95",
            "train.algorithm.entropy_coef=0.005",
            "train.actor.hidden_dims=[128, 128, 64]",
            "train.critic.hidden_dims=[128, 128, 64]",
            # Measured with the released quartic (the archived forward-only set); the envelope recipe study
            # (docs/recipe-study.md, E15-E17) changes the term together with the commands.
            "rewards.yaw_tracking=released_quartic",
        ),
    ),
}
# cpu_fast plus the changes of the recipe study (docs/recipe-study.md) under which ORC-111 follows its
# oscillators: with coupling, robots standing at sigma = 4 pull their phases together and moving robots
# then share one phase pattern, so the policy never learns to follow the others. Fewer standing commands
# (v_x from {1, 2} m/s, 10 % of draws still all-zero) and a quarter of the episodes without coupling,
# started in the four ideal gaits, keep every gait in the training data (E3, E9, E13); mirror augmentation
# makes the left and right legs carry alike, which removes a second, irregular gait that coupled robots
# otherwise fall into when one leg is lighter than its diagonal partner (E14).
PROFILES["cpu_oscillators"] = Profile(
    "cpu_fast with 10 % standing commands instead of about half, a quarter of the episodes run with sigma = 0 "
    "from one of the four ideal gaits, left-right mirror augmentation, 600 iterations: ORC-111 then walks the "
    "gait its oscillators start in and, coupled, settles into trot (docs/recipe-study.md)",
    PROFILES["cpu_fast"].overrides + (
        "train.max_iterations=600",
        "commands.lin_vel_x_choices=[1.0, 2.0]",
        "commands.zero_planar_prob=0.0",
        "osc.coupling_off_prob=0.25",
        "osc.uncoupled_init=any_gait",
        "train.algorithm.symmetry_cfg.use_data_augmentation=true",
    ),
    tasks=("mini_cheetah_osc",),
)
# The command envelope's recipe (issue 26; docs/recipe-study.md, E15, E27, E36, E52): cpu_oscillators
# with the paper's kinds of command (backwards, sideways, turning, on the spot) and the squared-exponential
# yaw term, trained in two stages: tracking errors relative to the command for 600 iterations, so that the
# robots learn speed, then absolute errors and doubled phase rewards, so that they reach the envelope's
# edges and keep to their oscillators. In the second stage three-eighths of the episodes run uncoupled,
# bound drawn three times as often as each other gait among their starts: at 1 m/s the slow gaits are only
# walked when they get enough of that data (E30, E31, E36); from the start, that share slows the first
# stage and leaves coupled robots settling worse (E39). The paper's [256, 256, 128] networks and a charge on
# every swing contact in the second stage stop the slow gaits swinging between checkpoints, which they did with
# [128, 128, 64] and without the charge (E42-E50): with both, the last checkpoint meets both goals on three
# seeds (E52). 1600 iterations, not E52's 1200: at 1200 ORC-110, trained uncoupled, undershoots 3 m/s on both seeds,
# and 400 more meet it ("ORC-110 with a longer budget"), so every configuration gets them. The CPU recipe of
# mini_cheetah_osc: about 100 minutes on two idle cores (ORC-100 seed 0: 68.9 for its first 1200).
PROFILES["cpu_envelope"] = Profile(
    "cpu_oscillators with the paper's kinds of command (v_x from {-1, 0, 1, 2, 3} m/s, v_y +-0.75, yaw +-2, "
    "20 % turns on the spot), [256, 256, 128] networks, 1600 iterations: relative tracking errors, then from "
    "iteration 600 absolute ones, phase rewards of 10 and every swing contact charged (5), 3/8 of the episodes "
    "uncoupled with bound drawn 3x, both tracking terms four times heavier (docs/recipe-study.md, E52, then 400 more "
    "iterations)",
    PROFILES["cpu_oscillators"].overrides + (
        "train.max_iterations=1600",
        "train.save_interval=100",
        "rewards.yaw_tracking=sqexp",
        "osc.standing_rule=command",
        "commands.lin_vel_x_choices=[-1.0, 0.0, 1.0, 2.0, 3.0]",
        "commands.lin_vel_y=[-0.75, 0.75]",
        "commands.yaw_rate=[-2.0, 2.0]",
        "commands.zero_planar_prob=0.2",
        "rewards.second_stage.start_step=14400",  # iteration 600 at 24 steps per iteration
        "rewards.second_stage.tracking_error=absolute",
        "train.actor.hidden_dims=[256, 256, 128]",
        "train.critic.hidden_dims=[256, 256, 128]",
        # Both tracking terms four times heavier with the doubled phase rewards: a gait locked at the wrong speed
        # then pays less than the command (recipe study, "Both tracking terms four times heavier").
        "rewards.second_stage.weights={swing_grf: 10.0, stance_grf: 10.0, swing_contact: 5.0, "
        "tracking_lin_vel: 16.0, tracking_ang_vel: 8.0}",
        "osc.second_stage.start_step=14400",
        "osc.second_stage.coupling_off_prob=0.375",
        "osc.second_stage.uncoupled_gait_weights=[1.0, 1.0, 3.0, 1.0]",
    ),
    tasks=("mini_cheetah_osc",),
)


def profile_setting(name: str, key: str) -> str | None:
    """The value a profile gives `key` (its last override of it), as written; None when it leaves it."""
    values = [item.partition("=")[2].strip() for item in PROFILES[name].overrides
              if item.partition("=")[0].strip() == key]
    return values[-1] if values else None


def profile_overrides(name: str | None, task: str | None = None) -> list[str]:
    if not name:
        return []
    if name not in PROFILES:
        raise ConfigError(f"unknown profile {name!r}; known profiles: {', '.join(PROFILES)}")
    profile = PROFILES[name]
    if task is not None and profile.tasks and task not in profile.tasks:
        raise ConfigError(f"profile {name!r} is for task {', '.join(profile.tasks)}, not {task!r}; "
                          f"profiles for every task: {', '.join(n for n, p in PROFILES.items() if not p.tasks)}")
    return list(profile.overrides)


# --- overrides --------------------------------------------------------------------------------


def split_overrides(overrides: list[str]) -> tuple[list[str], list[str]]:
    """(env overrides, train overrides with the 'train.' prefix removed)."""
    env, train = [], []
    for item in overrides:
        if item.strip().startswith(TRAIN_PREFIX):
            train.append(item.strip()[len(TRAIN_PREFIX) :])
        else:
            env.append(item)
    return env, train


def apply_split_overrides(env_cfg: Any, train_cfg: TrainCfg, overrides: list[str]) -> tuple[Any, TrainCfg]:
    """Apply mixed env/train overrides; returns new configs (the inputs are not changed)."""
    env_items, train_items = split_overrides(overrides)
    train_fields = {f.name for f in dataclasses.fields(train_cfg)}
    env_fields = {f.name for f in dataclasses.fields(env_cfg)}
    for item in env_items:
        first = item.partition("=")[0].strip().split(".")[0]
        if first in train_fields and first not in env_fields:
            raise ConfigError(
                f"override {item!r} names a train config key; prefix it with 'train.' (train.{item.strip()})"
            )
    try:
        train_cfg = apply_overrides(train_cfg, train_items)
    except ConfigError as err:
        raise ConfigError(f"train config (keys after 'train.'): {err}") from None
    return apply_overrides(env_cfg, env_items), train_cfg


# --- the dict rsl-rl wants --------------------------------------------------------------------


def _rsl_rl_classes() -> dict[str, Any]:
    from rsl_rl.algorithms import PPO
    from rsl_rl.models import MLPModel
    from rsl_rl.modules.distribution import GaussianDistribution

    return {"PPO": PPO, "MLPModel": MLPModel, "GaussianDistribution": GaussianDistribution}


def to_rsl_rl_dict(cfg: TrainCfg) -> dict:
    """A fresh OnPolicyRunner train_cfg dict (rsl-rl-lib 5.5): a new one per runner, since rsl-rl mutates it.

    Known class names become the classes themselves; any other name is left for rsl-rl to resolve.
    """
    data = to_dict(cfg)
    classes = _rsl_rl_classes()

    def resolve(block: dict) -> dict:
        block = {k: v for k, v in block.items() if v is not None}
        block["class_name"] = classes.get(block["class_name"], block["class_name"])
        if isinstance(block.get("distribution_cfg"), dict):
            block["distribution_cfg"] = resolve(block["distribution_cfg"])
        return block

    algorithm = resolve(data["algorithm"])
    symmetry = algorithm.pop("symmetry_cfg")
    if cfg.algorithm.symmetry_cfg.enabled:
        from learning.symmetry import mirror_augmentation

        algorithm["symmetry_cfg"] = {**symmetry, "data_augmentation_func": mirror_augmentation}
    return {
        "num_steps_per_env": data["num_steps_per_env"],
        "save_interval": data["save_interval"],
        "check_for_nan": data["check_for_nan"],
        "obs_groups": {k: list(v) for k, v in data["obs_groups"].items()},
        "algorithm": algorithm,
        "actor": resolve(data["actor"]),
        "critic": resolve(data["critic"]),
        "logger": logger_cfg(cfg),
        "experiment_name": data["experiment_name"],
        "run_name": data["run_name"],
    }


# --- loggers ----------------------------------------------------------------------------------


def logger_cfg(cfg: TrainCfg) -> str | dict:
    """rsl-rl's `logger` entry: 'tensorboard', or the writer class with its project."""
    if cfg.logger not in LOGGERS:
        raise ConfigError(f"logger {cfg.logger!r} is unknown; choose one of {', '.join(LOGGERS)}")
    spec = LOGGERS[cfg.logger]
    return "tensorboard" if spec is None else {"class_name": spec[1], "project_name": cfg.log_project_name}


def check_logger_ready(cfg: TrainCfg, environ: dict | None = None) -> None:
    """Fail before anything is written when the chosen logger's package or credentials are missing."""
    import importlib.util
    import os

    logger_cfg(cfg)
    spec = LOGGERS[cfg.logger]
    if spec is None:
        return
    package, _, variables = spec
    if importlib.util.find_spec(package) is None:
        raise ConfigError(f"--logger {cfg.logger} needs the {package} package: pip install -e \".[{cfg.logger}]\"")
    environ = os.environ if environ is None else environ
    missing = [v for v in variables if not environ.get(v)]
    if missing:
        raise ConfigError(f"--logger {cfg.logger} needs {' and '.join(missing)} in the environment")


def derived_experiment_name(task: str, env_cfg: Any) -> str:
    osc = getattr(env_cfg, "osc", None)
    return f"ORC_{osc.orc}" if osc is not None else task
