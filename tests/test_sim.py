"""The Mini Cheetah model and the CPU batch backend."""

import importlib
import sys

import numpy as np
import pytest
import torch

from gym_envs.sim import SimSetupError

SUBSTEPS = 5


def hold_default(sim, seconds):
    """Step with targets at the default pose; return the per-control-step results."""
    targets = sim.default_joint_pos.expand(sim.num_envs, -1).clone()
    steps = round(seconds / (sim.timestep * SUBSTEPS))
    return [sim.step(targets, SUBSTEPS) for _ in range(steps)]


def test_model_facts_come_from_the_model(make_sim):
    sim = make_sim()
    assert sim.robot_mass == pytest.approx(8.95, abs=0.05)
    assert sim.timestep == pytest.approx(0.002)
    assert sim.joint_names[:3] == ("RF_haa", "RF_hfe", "RF_kfe")
    assert sim.joint_names[9:] == ("LH_haa", "LH_hfe", "LH_kfe")
    assert torch.equal(sim.torque_limits, torch.tensor([18.0, 18.0, 28.0] * 4))
    assert torch.allclose(sim.joint_pos_limits[:3, 1], torch.tensor([1.5, 2.6, 2.7]))


def test_robot_settles_upright_and_stays(make_sim):
    sim = make_sim(num_envs=2)
    hold_default(sim, 2.0)  # falls from 0.35 m onto its feet and settles
    results = hold_default(sim, 5.0)
    heights = torch.stack([r.state.base_pos[:, 2] for r in results])
    assert heights.min() > 0.22 and heights.max() < 0.34
    assert heights.max() - heights.min() < 0.002  # it stays put, it does not drift down
    # Upright: tilted less than 10 degrees. The weak servos let the hind legs sag more than
    # the front ones, so the body rests about 8 degrees nose-up.
    upright = torch.stack([r.state.base_quat[:, 0].abs() for r in results])
    assert upright.min() > np.cos(np.radians(10) / 2)
    assert torch.all(results[-1].state.termination_force == 0)


def test_standing_foot_forces_carry_the_weight(make_sim):
    sim = make_sim(num_envs=2)
    result = hold_default(sim, 2.0)[-1]
    total = result.foot_forces.sum(dim=-1)  # (N, substeps): every substep, not only the last
    assert torch.allclose(total, torch.full_like(total, sim.robot_weight), rtol=0.05)
    assert result.joint_torques.shape == (2, SUBSTEPS, 12)
    assert torch.all(result.joint_torques.abs() <= sim.torque_limits + 1e-4)


def test_friction_randomisation_differs_per_env(make_sim):
    sim = make_sim(num_envs=2)
    hold_default(sim, 1.0)
    sim.set_ground_friction(torch.tensor([0, 1]), torch.tensor([0.05, 1.0]))
    assert np.allclose(sim.ground_friction(), [0.05, 1.0])
    sim.push_base(torch.tensor([0, 1]), torch.tensor([[1.5, 0.0], [1.5, 0.0]]))
    start = sim.read_state().base_pos[:, 0].clone()
    hold_default(sim, 0.5)
    travelled = sim.read_state().base_pos[:, 0] - start
    assert travelled[0] > travelled[1] + 0.05  # the slippery floor lets the robot slide further


def test_added_mass_is_physical(make_sim):
    sim = make_sim(num_envs=2)
    sim.set_base_mass_offset(torch.tensor([1]), torch.tensor([0.5]))
    result = hold_default(sim, 2.0)[-1]
    assert sim.batch.get_model(1).body_subtreemass[1] == pytest.approx(sim.robot_mass + 0.5)
    weights = result.foot_forces[:, -1].sum(dim=-1)
    assert weights[1] > weights[0] + 0.25 * sim.gravity  # part of the extra load goes through the hind shanks
    assert result.state.base_pos[1, 2] < result.state.base_pos[0, 2]


def test_same_inputs_same_outputs_at_any_thread_count(make_sim):
    # Bitwise, and on any processor: the batch is the same size, and each world is stepped by the same
    # code whichever thread takes it. Different batch sizes are never compared bitwise (issue 21).
    runs = []
    for threads in (1, 2):
        sim = make_sim(num_envs=6, num_threads=threads)
        gen = torch.Generator().manual_seed(0)
        steps = []
        for _ in range(50):
            targets = sim.default_joint_pos + 0.3 * torch.randn(6, 12, generator=gen)
            steps.append(sim.step(targets, SUBSTEPS))
        runs.append(steps)
    for a, b in zip(*runs):
        assert torch.equal(a.foot_forces, b.foot_forces)
        assert torch.equal(a.joint_torques, b.joint_torques)
        assert torch.equal(a.state.joint_pos, b.state.joint_pos)
        assert torch.equal(a.state.base_pos, b.state.base_pos)


def test_divergence_is_reported_not_raised(make_sim):
    sim = make_sim(num_envs=3)
    hold_default(sim, 0.2)
    sim._qvel[1, :] = 1e12  # a blown-up state, as an unstable simulation produces
    result = sim.step(sim.default_joint_pos.expand(3, -1).clone(), SUBSTEPS)
    assert result.diverged.tolist() == [False, True, False]
    assert torch.isfinite(result.state.joint_vel).all() and torch.isfinite(result.foot_forces).all()
    assert not hold_default(sim, 0.1)[-1].diverged.any()  # the batch goes on


def test_reset_writes_the_given_state(make_sim):
    sim = make_sim(num_envs=3)
    hold_default(sim, 0.3)
    ids = torch.tensor([0, 2])
    pos = torch.tensor([[0.0, 0.0, 0.5], [1.0, 2.0, 0.4]])
    quat = torch.tensor([[1.0, 0, 0, 0], [1.0, 0, 0, 0]])
    lin = torch.tensor([[0.3, 0, 0], [0, 0.2, 0]])
    joints = sim.default_joint_pos.expand(2, -1) + 0.1
    sim.reset(ids, pos, quat, lin, torch.zeros(2, 3), joints, torch.zeros(2, 12))
    state = sim.read_state()
    assert torch.allclose(state.base_pos[ids], pos)
    assert torch.allclose(state.base_lin_vel[ids], lin)
    assert torch.allclose(state.joint_pos[ids], joints)
    assert state.base_pos[1, 2] < 0.3  # env 1 untouched


def test_copy_state_to_mjdata_for_rendering(make_sim):
    import mujoco

    sim = make_sim(num_envs=2)
    hold_default(sim, 0.2)
    sim.push_base(torch.tensor([1]), torch.tensor([[0.5, 0.0]]))
    data = mujoco.MjData(sim.model)
    sim.copy_state_to(1, data)
    assert np.allclose(data.qpos[:3], sim.read_state().base_pos[1].numpy(), atol=1e-6)
    assert data.qvel[0] == pytest.approx(sim.read_state().base_lin_vel[1, 0].item(), abs=1e-6)


def test_missing_model_file_is_named(make_sim):
    with pytest.raises(SimSetupError, match="model file not found: '/nope/robot.xml'"):
        make_sim(model_path="/nope/robot.xml")


def test_malformed_model_file_is_named(make_sim, tmp_path):
    bad = tmp_path / "broken.xml"
    bad.write_text("<mujoco><worldbody><body name='base'><geom type='box'/></worldbody></mujoco>")
    with pytest.raises(SimSetupError, match="broken.xml' does not compile"):
        make_sim(model_path=str(bad))


def test_wrong_control_shape_is_named(make_sim):
    sim = make_sim(num_envs=2)
    with pytest.raises(ValueError, match=r"shape \(2, 12\).*got \(2, 11\)"):
        sim.step(torch.zeros(2, 11), SUBSTEPS)


def test_missing_warp_extra_is_named(monkeypatch):
    monkeypatch.setitem(sys.modules, "mujoco_warp", None)  # importing it now raises ImportError
    monkeypatch.delitem(sys.modules, "gym_envs.sim.mujoco_warp", raising=False)
    with pytest.raises(SimSetupError, match=r"^the 'warp' backend needs the gpu extra: pip install -e \.\[gpu\]$"):
        importlib.import_module("gym_envs.sim.mujoco_warp")


def test_unknown_backend_is_named():
    from gym_envs.sim import make_backend

    with pytest.raises(SimSetupError, match="unknown simulation backend 'bullet'; choose one of mujoco, warp"):
        make_backend("bullet")
