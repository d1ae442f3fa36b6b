"""What learning/ relies on in rsl-rl-lib, checked by behaviour: fails loudly when an upgrade changes it.

learning/runner.py runs rsl-rl's own `OnPolicyRunner.learn` and hangs its conventions on the Logger
callbacks the loop calls (after every env step, after every update, at the start and the end).
These tests train tiny runs through that loop and check what a user sees: checkpoint names and
contents, tensorboard steps, a resumed run continuing at the right iteration, a stop that saves,
the progress line's numbers. setup.py pins rsl-rl-lib to the minor version this file was checked
against; moving the pin means running this file first.
"""

from __future__ import annotations

import os
import re
from importlib.metadata import version

import torch
from rsl_rl.env import VecEnv
from rsl_rl.runners import OnPolicyRunner
from rsl_rl.utils.log_writer import LogWriter
from rsl_rl.utils.utils import resolve_callable

from learning import runs
from learning.runner import StopRequest
from tests.test_cli import _scalars
from tests.test_learning import one_torch_thread, small_env, small_runner  # noqa: F401 (autouse fixture)

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_installed_rsl_rl_is_inside_the_pinned_range():
    setup = open(os.path.join(REPO, "setup.py")).read()
    low, high = re.search(r'"rsl-rl-lib>=([\d.]+),<([\d.]+)"', setup).groups()
    installed = tuple(int(x) for x in version("rsl-rl-lib").split(".")[:2])
    as_tuple = lambda v: tuple(int(x) for x in v.split("."))  # noqa: E731
    assert as_tuple(low) <= installed < as_tuple(high), (
        f"rsl-rl-lib {version('rsl-rl-lib')} is outside setup.py's range >={low},<{high}: check this file's contract "
        "against the new version, then move the pin"
    )


def test_rsl_rl_runs_the_loop_and_the_callbacks_fire_per_step_and_per_iteration(tmp_path, monkeypatch, capsys):
    loops, steps, iterations = [], [], []
    original = OnPolicyRunner.learn
    monkeypatch.setattr(OnPolicyRunner, "learn", lambda self, *a, **k: (loops.append(a), original(self, *a, **k))[1])
    runner = small_runner(small_env(8), log_dir=str(tmp_path), steps=3, save_interval=2)
    after_step, after_iteration = runner.logger.after_step, runner.logger.after_iteration
    runner.logger.after_step = lambda: (steps.append(1), after_step())
    runner.logger.after_iteration = lambda n: (iterations.append(n), after_iteration(n))
    assert runner.learn(3, init_at_random_ep_len=True)
    assert loops == [(3, True)]  # rsl-rl's learn, called once with what we were given
    assert (len(steps), iterations) == (9, [1, 2, 3])
    assert runs.list_checkpoints(str(tmp_path)) == [0, 2, 3]
    assert [torch.load(runs.checkpoint_path(str(tmp_path), n), weights_only=True)["iter"] for n in (0, 2, 3)] == [0, 2, 3]
    assert _scalars(str(tmp_path), "Loss/value") == [0, 1, 2]  # event steps are iteration indices
    lines = [line for line in capsys.readouterr().out.splitlines() if re.search(r"\bit \d/3\b", line)]
    assert [re.search(r"\bit (\d)/3", line).group(1) for line in lines] == ["1", "2", "3"]
    assert runner.logger.writer is None  # closed at the end


def test_a_resumed_runner_continues_at_the_checkpoints_iteration(tmp_path):
    first = tmp_path / "first"
    runner = small_runner(small_env(8), log_dir=str(first), steps=2)
    runner.learn(2)
    resumed = small_runner(small_env(8), log_dir=str(tmp_path / "second"), steps=2)
    resumed.load(runs.checkpoint_path(str(first), 2))
    assert resumed.learn(2)
    assert runs.list_checkpoints(str(tmp_path / "second")) == [4]
    assert _scalars(str(tmp_path / "second"), "Loss/value") == [2, 3]
    assert resumed.current_learning_iteration == 4


def test_a_stop_after_an_update_saves_that_iteration_and_closes_the_writer(tmp_path):
    runner = small_runner(small_env(8), log_dir=str(tmp_path), steps=2)
    stop = StopRequest()
    after_iteration = runner.logger.after_iteration

    def stop_after_two(n):
        stop.requested = n == 2
        after_iteration(n)

    runner.logger.after_iteration = stop_after_two
    assert runner.learn(50, stop=stop) is False
    assert runs.list_checkpoints(str(tmp_path)) == [0, 2]
    assert runner.current_learning_iteration == 2 and runner.alg.storage.step == 0
    assert runner.logger.writer is None


def test_the_progress_numbers_come_from_rsl_rls_episode_buffers(tmp_path):
    runner = small_runner(small_env(8, episode_length_s=0.1), log_dir=str(tmp_path), steps=12)
    runner.learn(1, init_at_random_ep_len=False)
    logger = runner.logger
    assert len(logger.lenbuffer) >= 8 and logger.last_reward is not None  # every robot's 10-step episode ended
    assert logger.last_tracking_error is not None  # the task's Episode/tracking_error reached ep_extras


def test_vec_env_contract_is_what_the_adapter_implements():
    abstract = set(getattr(VecEnv, "__abstractmethods__", set()))
    assert abstract <= {"get_observations", "step", "reset"}, f"VecEnv now also requires {abstract}"


def test_logger_names_rsl_rl_resolves():
    for name in ("WandbLogWriter", "NeptuneLogWriter"):
        assert issubclass(resolve_callable(name), LogWriter), f"rsl-rl no longer resolves {name}"
