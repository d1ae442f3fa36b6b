"""No tensor on the wrong device, checked on a CPU-only machine.

A tensor made without `device=` lands on torch's default device. On a CUDA run that is the CPU,
beside the env's tensors on the GPU, and the first op mixing them raises; on a CPU-only machine the
two are one device and nothing fails. With the default device set to 'meta' (shapes, no data)
while the env runs on an explicit CPU device, such a tensor meets the env's CPU tensors and raises
here too. Networks are loaded outside that scope: rsl-rl builds its modules on the default device
and moves them, which is right on any machine.
"""

from __future__ import annotations

import itertools

import pytest
import torch

from analysis import rollout
from gym_envs import env_cfg_class, make_env, oscillators
from learning import export, runs

from .test_export import shipped_session

ALL_ORC = ["".join(bits) for bits in itertools.product("01", repeat=3)]
STEPS = 8  # episodes of 5 steps: every robot resets at least once


def forgotten_device_fails():
    return torch.device("meta")


def stepped_env(task="mini_cheetah_osc", **osc):
    """A few control steps of 3 robots on the CPU, with short episodes so resets run too."""
    cfg = env_cfg_class(task)()
    cfg.env.num_envs, cfg.env.device, cfg.sim.num_threads = 3, "cpu", 1
    cfg.env.episode_length_s = 0.05
    cfg.init_state.timeout_reset_ratio = 1.0
    for key, value in osc.items():
        setattr(cfg.osc, key, value)
    env = make_env(task, cfg)
    for _ in range(STEPS):
        obs, rew, done, extras = env.step(torch.randn(3, env.num_actions, device="cpu"))
    assert obs["actor"].device.type == "cpu" and torch.isfinite(obs["critic"]).all() and torch.isfinite(rew).all()
    assert env.episode_length_buf.max() < STEPS  # the reset path ran
    return env


@pytest.mark.parametrize("init", oscillators.PHASE_INIT_MODES)
def test_every_phase_init_mode_keeps_to_the_env_device(init):
    # Half the episodes uncoupled and started from another mode: the second initial_phases call.
    uncoupled = "pace" if init == "any_gait" else "any_gait"
    with forgotten_device_fails():
        env = stepped_env(init=init, coupling_off_prob=0.5, uncoupled_init=uncoupled)
    assert env.phase.device.type == "cpu" and torch.all((env.phase >= 0) & (env.phase < 2 * torch.pi))


def test_every_orc_and_the_plain_task_keep_to_the_env_device():
    with forgotten_device_fails():
        for orc in ALL_ORC:
            stepped_env(orc=orc)
        stepped_env(standing_rule="command")
        stepped_env("mini_cheetah")


def test_controller_export_and_evaluation_rollout_keep_to_their_devices(tmp_path):
    session = shipped_session(tmp_path)
    actor = session.policy.model.as_onnx(verbose=False).cpu().eval()
    run = rollout.load_policy_run(runs.shipped_policy_dir("111"))
    # torch.onnx.export itself does not run under a meta default device; what it traces is ours.
    with forgotten_device_fails():
        metadata = export.deployment_metadata(session.task)
        controller = export.Controller(actor, session.task).eval()
        targets, phase = controller(*controller.example_inputs())
        (result,) = rollout.run_jobs([rollout.Job(run, 2)], num_steps=5, progress=False, num_threads=1)
    assert metadata["default_joint_pos"] == pytest.approx(session.task.default_joint_pos.tolist())
    assert targets.shape == (1, 12) and torch.isfinite(targets).all() and phase.shape == (1, 4)
    assert result.data["phase"].shape[:2] == (2, 5)
