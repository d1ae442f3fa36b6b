"""Deployment export: metadata, and the whole controller (onnxruntime) driving the simulator like play.py."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import play
from gym_envs.legged_robot import quat_rotate_inverse
from learning import export

STEPS = 200


def shipped_session(tmp_path, *extra):
    """play.py's evaluation session of the shipped ORC-111 policy, one robot."""
    argv = ["--orc", "111", "--log_root", str(tmp_path / "no_runs"), "--num_envs", "1", "--num_threads", "1",
            "--command", "1.0", "--osc_init", "trot", *extra]
    return play.Session(play.build_parser().parse_args(argv))


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("export")
    session = shipped_session(tmp)
    paths = export.export_deployment(session.policy.model, session.task, str(tmp / "exported"), session.checkpoint)
    return tmp, session, paths


def test_export_writes_policy_and_controller_with_metadata(exported):
    _, session, paths = exported
    assert [p.rsplit("/", 1)[-1] for p in paths] == ["policy.pt", "policy.onnx", "controller.onnx"]
    for path in paths[1:]:
        meta = export.read_metadata(path)
        terms = [t["term"] for t in meta["observation"]]
        assert terms == list(session.task.cfg.observations.actor)
        assert sum(t["width"] for t in meta["observation"]) == session.policy.model.obs_dim
        commands = next(t for t in meta["observation"] if t["term"] == "commands")
        assert commands["scale"] == [3.0, 1.0, 3.0]
        assert meta["action_scale"] == pytest.approx([0.2, 0.3, 0.3] * 4)
        assert meta["kp"] == pytest.approx([20.0] * 12) and meta["kd"] == pytest.approx([0.5] * 12)
        assert meta["control_hz"] == pytest.approx(100.0) and meta["physics_hz"] == pytest.approx(500.0)
        assert meta["default_joint_pos"] == pytest.approx(session.task.default_joint_pos.tolist())
        osc = meta["oscillators"]
        assert osc["orc"] == "111" and osc["coupling_enabled"] and osc["legs"] == ["RF", "LF", "RH", "LH"]
        assert osc["grf_normaliser"] == pytest.approx(float(session.task.grf_normaliser))
        assert osc["standing"] == {"omega": 1.0, "sigma": 4.0, "xi": 1.0}
        assert list(meta["controller"]["inputs"])[-1] == "phase"


def test_exported_controller_drives_the_simulator_like_play(exported, tmp_path):
    """Closed loop: the ONNX controller on the raw simulator reproduces play.py's rollout for 200 steps."""
    import onnxruntime

    _, reference, paths = exported
    controller = onnxruntime.InferenceSession(paths[2])
    driven = shipped_session(tmp_path)  # same seed: an identical start
    ref, task = reference.task, driven.task
    ref.reset(), task.reset()

    # The env's first observation holds the initial phases, before any substep: both take that step
    # with the torch policy; from then on the controller integrates the forces of the period before.
    phase = task.phase.clone()
    with torch.inference_mode():
        reference.env.step(reference.policy(reference.env.get_observations()))
        driven.env.step(driven.policy(driven.env.get_observations()))
    state, forces = task.state, task.foot_forces
    targets = task.default_joint_pos + task.target_history[0]
    gravity = torch.tensor([[0.0, 0.0, -1.0]])
    worst = 0.0
    for step in range(STEPS):
        feed = {
            "base_ang_vel": state.base_ang_vel, "projected_gravity": quat_rotate_inverse(state.base_quat, gravity),
            "joint_pos": state.joint_pos, "joint_vel": state.joint_vel, "previous_joint_targets": targets,
            "foot_forces": forces, "command": task.commands, "phase": phase,
        }
        new_targets, new_phase = controller.run(None, {k: v.numpy().astype(np.float32) for k, v in feed.items()})
        np.testing.assert_allclose(new_phase, ref.phase.numpy(), atol=1e-5, rtol=0, err_msg=f"step {step}")
        with torch.inference_mode():
            reference.env.step(reference.policy(reference.env.get_observations()))
        expected = (ref.default_joint_pos + ref.target_history[0]).numpy()
        worst = max(worst, float(np.abs(new_targets - expected).max()))
        np.testing.assert_allclose(new_targets, expected, atol=1e-5, rtol=0, err_msg=f"step {step}")
        assert not ref.terminated.any()
        targets, phase = torch.from_numpy(new_targets), torch.from_numpy(new_phase)
        result = task.sim.step(targets, task.decimation)
        state, forces = result.state, result.foot_forces
    print(f"largest joint-target difference over {STEPS} steps: {worst:.2e} rad")
    assert float(ref.base_lin_vel[0, 0]) > 0.5  # it walked, so the comparison covered contacts and swing


def test_controller_export_refuses_what_a_robot_cannot_run(exported, tmp_path):
    _, session, _ = exported
    policy = session.policy.model.as_onnx(verbose=False)
    session.task.cfg.osc.hold_grf = True
    try:
        with pytest.raises(export.ConfigError, match="osc.hold_grf=true"):
            export.Controller(policy, session.task)
    finally:
        session.task.cfg.osc.hold_grf = False
    actor_terms = session.task.cfg.observations.actor
    session.task.cfg.observations.actor = ["base_lin_vel", *actor_terms]  # the simulator's, not the IMU's
    try:
        with pytest.raises(export.ConfigError, match="terms base_lin_vel need simulator state"):
            export.Controller(policy, session.task)
    finally:
        session.task.cfg.observations.actor = actor_terms
