"""PPO training configs as typed dataclasses (rsl-rl-lib's OnPolicyRunner settings), beside the env configs.

As in legged_gym, a task's learner settings live with its env settings and the registry pairs them
(`gym_envs.registry.register`); the defaults are the paper's (ORCAgym's MiniCheetahOscRunnerCfg, facts §7).
learning.runner_config turns one into the dict rsl-rl takes and holds the named profiles.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import ClassVar

from gym_envs.config import Check, ConfigError, OneOf, Range, check_values

TRAIN_PREFIX = "train."


def _known_task(name: str) -> bool:
    from gym_envs.registry import TASKS

    return name in TASKS


@dataclass
class SymmetryCfg:
    """rsl-rl's Symmetry extension with orcgym's left-right mirror (learning.symmetry); off unless a flag is set."""

    use_data_augmentation: bool = False  # every mini-batch also trains on its mirror image
    use_mirror_loss: bool = False  # penalise actions that differ from the mirrored actions of the mirrored state
    mirror_loss_coeff: float = 0.0

    @property
    def enabled(self) -> bool:
        return self.use_data_augmentation or self.use_mirror_loss


@dataclass
class AlgorithmCfg:
    """PPO (rsl_rl.algorithms.PPO keyword arguments). Values of mini_cheetah_osc (facts §7.1, §10.11)."""

    class_name: str = "PPO"
    num_learning_epochs: int = 4
    num_mini_batches: int = 8
    clip_param: float = 0.2  # also the clip range of the value loss
    gamma: float = 0.99  # 1 - 1/(1 s / 0.01 s)
    lam: float = 0.995  # 1 - 1/(2 s / 0.01 s)
    value_loss_coef: float = 1.0
    entropy_coef: float = 0.02
    learning_rate: float = 1e-5  # start value; the adaptive schedule keeps it in [1e-5, 1e-2]
    max_grad_norm: float = 1.0
    optimizer: str = "adam"
    use_clipped_value_loss: bool = True
    schedule: str = "adaptive"  # 'adaptive' (KL-driven) or 'fixed'
    desired_kl: float = 0.01
    normalize_advantage_per_mini_batch: bool = False
    symmetry_cfg: SymmetryCfg = field(default_factory=SymmetryCfg)


@dataclass
class DistributionCfg:
    """Action distribution of the actor (rsl_rl.modules.distribution)."""

    class_name: str = "GaussianDistribution"
    init_std: float = 1.0
    std_type: str = "scalar"  # std stored directly, as in ORCAgym; 'log' stores log-std


@dataclass
class ModelCfg:
    """An rsl_rl.models.MLPModel; a distribution makes it stochastic (the actor)."""

    class_name: str = "MLPModel"
    hidden_dims: tuple[int, ...] = (256, 256, 128)
    activation: str = "elu"
    obs_normalization: bool = True
    distribution_cfg: DistributionCfg | None = None


def _folder_name(name: str) -> bool:
    return os.sep not in name and name not in (".", "..")


_POSITIVE = Range(0.0, low_open=True)
_ACTIVATIONS = ("elu", "selu", "relu", "crelu", "lrelu", "tanh", "sigmoid", "softplus", "gelu", "swish", "mish",
                "identity")  # rsl_rl.utils.resolve_nn_activation


# --logger name -> (the package it needs, rsl-rl's writer class, environment variables the writer reads)
LOGGERS: dict[str, tuple[str, str, tuple[str, ...]] | None] = {
    "tensorboard": None,
    "wandb": ("wandb", "WandbLogWriter", ()),
    "neptune": ("neptune", "NeptuneLogWriter", ("NEPTUNE_API_TOKEN", "NEPTUNE_USERNAME")),
}


def _model_rules(name: str) -> dict:
    return {
        f"{name}.class_name": OneOf(("MLPModel",)),
        f"{name}.hidden_dims": (Check(len, "at least one hidden layer"), Range(1)),
        f"{name}.activation": OneOf(_ACTIVATIONS),
        f"{name}.distribution_cfg.class_name": OneOf(("GaussianDistribution",)),
        f"{name}.distribution_cfg.init_std": _POSITIVE,
        f"{name}.distribution_cfg.std_type": OneOf(("scalar", "log")),
    }


@dataclass
class TrainCfg:
    """Everything about learning; the env side lives in the task's env config."""

    # What the values may be beyond their types (floats must also be finite); see gym_envs.config.check_values.
    RULES: ClassVar[dict] = {
        "task": Check(_known_task, "a registered task (gym_envs.registry)"),
        "seed": Range(-1),
        "num_steps_per_env": Range(1),
        "max_iterations": Range(1),
        "save_interval": Range(1),
        "obs_normalization_frozen_from": Range(0),
        "experiment_name": Check(_folder_name, "a plain folder name (no path separator)"),
        "run_name": Check(_folder_name, "a plain folder name (no path separator)"),
        "logger": OneOf(tuple(LOGGERS)),
        # rsl-rl's Neptune writer prefixes the workspace (NEPTUNE_USERNAME) and a '/'; W&B takes the entity apart too
        "log_project_name": Check(lambda name: bool(name) and "/" not in name, "a project name without '/'"),
        "obs_groups": Check(lambda groups: groups and set(groups) <= {"actor", "critic"},
                            "a non-empty list of the env's observation groups, actor and critic"),
        "algorithm.class_name": OneOf(("PPO",)),
        "algorithm.num_learning_epochs": Range(1),
        "algorithm.num_mini_batches": Range(1),
        "algorithm.clip_param": _POSITIVE,
        "algorithm.gamma": Range(0.0, 1.0, low_open=True),
        "algorithm.lam": Range(0.0, 1.0),
        "algorithm.value_loss_coef": Range(0.0),
        "algorithm.entropy_coef": Range(0.0),
        "algorithm.learning_rate": _POSITIVE,
        "algorithm.max_grad_norm": _POSITIVE,
        "algorithm.optimizer": OneOf(("adam", "adamw", "sgd", "rmsprop")),  # rsl_rl.utils.resolve_optimizer
        "algorithm.schedule": OneOf(("adaptive", "fixed")),
        "algorithm.desired_kl": _POSITIVE,
        "algorithm.symmetry_cfg.mirror_loss_coeff": Range(0.0),
        **_model_rules("actor"),
        **_model_rules("critic"),
    }

    task: str = ""  # the registered task this config trains (set by the run); recorded so a run folder names its task
    seed: int = 0  # -1 draws one at start; the drawn value is what train.yaml records
    num_steps_per_env: int = 32
    max_iterations: int = 2000  # total PPO iterations of the run; a resumed run continues up to it
    save_interval: int = 50  # model_<it>.pt every this many iterations (and at 0 and the end)
    experiment_name: str = ""  # '' derives it: ORC_<orc> for oscillator tasks, else the task name
    run_name: str = ""  # '' derives it: seed<seed>
    init_at_random_ep_len: bool = True
    # Completed iteration from which the observation normalisers keep their statistics (0: they learn throughout);
    # a second stage can start on fixed inputs instead of inputs whose scaling still moves.
    obs_normalization_frozen_from: int = 0
    logger: str = "tensorboard"  # 'tensorboard', 'wandb' or 'neptune' (rsl-rl's writers; tensorboard events always)
    log_project_name: str = "orcgym"  # W&B / Neptune project
    check_for_nan: bool = True
    obs_groups: dict[str, tuple[str, ...]] = field(
        default_factory=lambda: {"actor": ("actor",), "critic": ("critic",)}
    )
    algorithm: AlgorithmCfg = field(default_factory=AlgorithmCfg)
    actor: ModelCfg = field(default_factory=lambda: ModelCfg(distribution_cfg=DistributionCfg()))
    critic: ModelCfg = field(default_factory=ModelCfg)
    # Provenance, written by train.py (setting them changes nothing):
    profile: str = ""  # the --profile the run was started with
    resumed_from: str = ""  # checkpoint a resumed run started from

    def validate(self, num_envs: int) -> None:
        """One-line ConfigError (keys with the 'train.' prefix) for a value outside RULES, or a batch
        too small for its mini-batches (num_envs robots per process)."""
        check_values(self, self.RULES, prefix=TRAIN_PREFIX)
        if self.actor.distribution_cfg is None:
            raise ConfigError("config key 'train.actor.distribution_cfg' is None; the actor needs a distribution")
        batch = num_envs * self.num_steps_per_env
        if self.algorithm.num_mini_batches > batch:
            raise ConfigError(
                f"config key 'train.algorithm.num_mini_batches' is {self.algorithm.num_mini_batches}; allowed: at "
                f"most the batch of env.num_envs x train.num_steps_per_env = {batch}"
            )
