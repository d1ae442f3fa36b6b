"""The rsl-rl-lib internals learning/ relies on: fails loudly, naming the piece, when an upgrade changes one.

learning/runner.py replaces OnPolicyRunner's training loop and logging, so it calls PPO, the models,
the storage and the Logger directly, and overrides methods whose signatures must stay compatible.
setup.py pins rsl-rl-lib to the minor version this file was checked against; moving the pin means
running this file first.
"""

from __future__ import annotations

import inspect
import os
import re
from importlib.metadata import version

import pytest
import rsl_rl.utils
from rsl_rl.algorithms import PPO
from rsl_rl.env import VecEnv
from rsl_rl.models import MLPModel
from rsl_rl.runners import OnPolicyRunner
from rsl_rl.utils.log_writer import LogWriter
from rsl_rl.utils.logger import Logger
from rsl_rl.utils.utils import resolve_callable

from learning.runner import TaskRunner

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def params(fn) -> list[str]:
    return [p for p in inspect.signature(fn).parameters if p != "self"]


def test_installed_rsl_rl_is_inside_the_pinned_range():
    setup = open(os.path.join(REPO, "setup.py")).read()
    low, high = re.search(r'"rsl-rl-lib>=([\d.]+),<([\d.]+)"', setup).groups()
    installed = tuple(int(x) for x in version("rsl-rl-lib").split(".")[:2])
    as_tuple = lambda v: tuple(int(x) for x in v.split("."))  # noqa: E731
    assert as_tuple(low) <= installed < as_tuple(high), (
        f"rsl-rl-lib {version('rsl-rl-lib')} is outside setup.py's range >={low},<{high}: check this file's contract "
        "against the new version, then move the pin"
    )


@pytest.mark.parametrize("fn, expected", [
    (OnPolicyRunner.__init__, ["env", "train_cfg", "log_dir", "device"]),
    (OnPolicyRunner.learn, ["num_learning_iterations", "init_at_random_ep_len"]),
    (OnPolicyRunner.save, ["path", "infos"]),
    (OnPolicyRunner.load, ["path", "load_cfg", "strict", "map_location"]),
    (OnPolicyRunner.get_inference_policy, ["device"]),
    (Logger.__init__, ["log_dir", "cfg", "env_cfg", "num_envs", "is_distributed", "gpu_world_size",
                       "gpu_global_rank", "device"]),
    (Logger.log, ["it", "start_it", "total_it", "collect_time", "learn_time", "loss_dict", "learning_rate",
                  "action_std", "rnd_weight", "print_minimal", "width", "pad"]),
    (Logger.process_env_step, ["rewards", "dones", "extras", "intrinsic_rewards"]),
    (Logger.init_logging_writer, []),
    (Logger.save_model, ["path", "it"]),
    (Logger.stop_logging_writer, []),
    (LogWriter.save_video, ["video", "it"]),
    (PPO.act, ["obs"]),
    (PPO.process_env_step, ["obs", "rewards", "dones", "extras"]),
    (PPO.compute_returns, ["obs"]),
    (PPO.update, []),
    (PPO.save, []),
    (PPO.load, ["loaded_dict", "load_cfg", "strict"]),
    (MLPModel.__init__, ["obs", "obs_groups", "obs_set", "output_dim", "hidden_dims", "activation",
                         "obs_normalization", "distribution_cfg"]),
    (MLPModel.as_jit, []),
    (MLPModel.as_onnx, ["verbose"]),
    (rsl_rl.utils.check_nan, ["obs", "rewards", "dones"]),
])
def test_called_and_overridden_signatures(fn, expected):
    got = params(fn)
    assert got[: len(expected)] == expected, f"rsl-rl's {fn.__qualname__} now takes {got}; learning/ passes {expected}"


def test_our_overrides_accept_what_rsl_rl_passes():
    for name in ("learn", "save", "load"):
        ours, theirs = params(getattr(TaskRunner, name)), params(getattr(OnPolicyRunner, name))
        assert ours[: len(theirs)] == theirs, f"TaskRunner.{name}{ours} no longer matches OnPolicyRunner.{name}{theirs}"


def test_vec_env_contract_is_what_the_adapter_implements():
    abstract = set(getattr(VecEnv, "__abstractmethods__", set()))
    assert abstract <= {"get_observations", "step", "reset"}, f"VecEnv now also requires {abstract}"


def test_runner_attributes_and_ppo_behaviour(tmp_path):
    """Build a small runner and touch every attribute and return value the loop uses."""
    from tests.test_learning import small_env, small_runner

    env = small_env(num_envs=8)
    runner = small_runner(env, steps=2)
    for attr in ("alg", "cfg", "env", "device", "is_distributed", "gpu_world_size", "gpu_global_rank",
                 "current_learning_iteration"):
        assert hasattr(runner, attr), f"OnPolicyRunner no longer sets self.{attr}"
    alg = runner.alg
    for attr in ("storage", "learning_rate", "actor", "critic"):
        assert hasattr(alg, attr), f"PPO no longer has .{attr}"
    assert isinstance(alg.actor.obs_dim, int) and isinstance(alg.critic.obs_dim, int)
    for method in ("train_mode", "eval_mode", "broadcast_parameters", "get_policy"):
        assert callable(getattr(alg, method, None)), f"PPO no longer has .{method}()"
    assert callable(getattr(alg.storage, "clear", None)), "RolloutStorage no longer has .clear()"
    assert callable(getattr(alg.get_policy(), "as_jit", None))
    assert "actor_state_dict" in alg.save(), "checkpoints no longer hold actor_state_dict (learning/runs.py reads it)"
    logger = runner.logger
    for attr in ("writer", "ep_extras", "rewbuffer", "lenbuffer", "tot_time", "disable_logs", "git_status_repos"):
        assert hasattr(logger, attr), f"rsl-rl's Logger no longer has .{attr}"
    assert runner.train(1, init_at_random_ep_len=False)
    assert runner.current_learning_iteration == 1
    assert alg.get_policy().output_std.shape[-1] == env.num_actions  # the progress line logs it


def test_logger_names_rsl_rl_resolves():
    for name in ("WandbLogWriter", "NeptuneLogWriter"):
        assert issubclass(resolve_callable(name), LogWriter), f"rsl-rl no longer resolves {name}"
