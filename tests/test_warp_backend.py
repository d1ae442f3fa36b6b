"""The MuJoCo Warp backend against the CPU backend, on Warp's CPU device with a few envs.

Warp compiles its kernels on first use (about 40 s cold on CPU, cached afterwards in
~/.cache/warp); the sims are built once per module to pay that once.
"""

import mujoco
import numpy as np
import pytest
import torch

pytest.importorskip("mujoco_warp")

from gym_envs.sim import make_backend  # noqa: E402

from .conftest import FOOT_SENSORS, SCENE  # noqa: E402

SUBSTEPS = 5


def build(name, num_envs, **kwargs):
    extra = {"warp_device": "cpu"} if name == "warp" else {"num_threads": 1}
    return make_backend(
        name,
        model_path=SCENE,
        num_envs=num_envs,
        foot_sensors=FOOT_SENSORS,
        termination_sensors=("base_force",),
        **extra,
        **kwargs,
    )


def hold_default(sim, seconds):
    targets = sim.default_joint_pos.expand(sim.num_envs, -1).clone()
    steps = round(seconds / (sim.timestep * SUBSTEPS))
    return [sim.step(targets, SUBSTEPS) for _ in range(steps)]


@pytest.fixture(scope="module")
def standing():
    """Both backends after 2 s of holding the home pose (falling from 0.35 m and settling)."""
    warp_sim, cpu_sim = build("warp", 2), build("mujoco", 2)
    return warp_sim, hold_default(warp_sim, 2.0), cpu_sim, hold_default(cpu_sim, 2.0)


def test_model_facts_match_the_cpu_backend(standing):
    warp_sim, _, cpu_sim, _ = standing
    for name in ("joint_names", "foot_names", "robot_mass", "gravity", "timestep"):
        assert getattr(warp_sim, name) == getattr(cpu_sim, name)
    for name in ("default_joint_pos", "joint_pos_limits", "torque_limits"):
        assert torch.equal(getattr(warp_sim, name), getattr(cpu_sim, name))


def test_standing_height_and_weight_match_the_cpu_backend(standing):
    warp_sim, warp_steps, _, cpu_steps = standing
    last = warp_steps[-1]
    height = last.state.base_pos[:, 2]
    assert torch.allclose(height, cpu_steps[-1].state.base_pos[:, 2], atol=0.005)
    assert height.min() > 0.22 and height.max() < 0.34
    total = last.foot_forces.sum(dim=-1)  # (N, substeps)
    assert torch.allclose(total, torch.full_like(total, warp_sim.robot_weight), rtol=0.05)
    assert last.foot_forces.shape == (2, SUBSTEPS, 4) and last.joint_torques.shape == (2, SUBSTEPS, 12)
    assert torch.all(last.joint_torques.abs() <= warp_sim.torque_limits + 1e-4)
    assert torch.all(last.state.termination_force == 0) and not last.diverged.any()


def test_one_control_step_from_the_same_state_agrees(standing):
    """Both backends are reset to the CPU's standing state and take one step to random targets.

    The models are the same and the reset clears the warm starts in both, so what is
    left is arithmetic: float32 (Warp) against float64 (CPU), and solver details (MJWarp's
    Newton solver stops on its float32 tolerance, within the same 10 iterations). A joint
    angle near 1.6 rad is stored to 1.2e-7 rad in float32; the servo torque 20 (q* - q)
    - 0.5 dq then differs by a few 1e-6 N m, and the stiff foot contacts (forces of
    20-70 N on ~1 mm of penetration) by a few 1e-4 N. Measured over 5 seeds: angles and
    positions within 1.2e-7, velocities 8e-6, torques 7e-6 N m, foot forces 3.6e-4 N.
    The tolerances below are 15-80x those, to leave room for another CPU's float32 (FMA
    contraction, vector widths), and still a thousand times below anything physical.
    """
    warp_sim, _, cpu_sim, _ = standing
    state = cpu_sim.read_state()
    ids = torch.arange(2)
    zeros = torch.zeros(2, 3)
    for sim in (warp_sim, cpu_sim):
        sim.reset(ids, state.base_pos, state.base_quat, zeros, zeros, state.joint_pos, torch.zeros(2, 12))
    gen = torch.Generator().manual_seed(1)
    targets = cpu_sim.default_joint_pos + 0.2 * torch.randn(2, 12, generator=gen)
    w, c = warp_sim.step(targets, SUBSTEPS), cpu_sim.step(targets, SUBSTEPS)
    assert torch.allclose(w.state.joint_pos, c.state.joint_pos, rtol=0, atol=1e-5)
    assert torch.allclose(w.state.base_pos, c.state.base_pos, rtol=0, atol=1e-5)
    assert torch.allclose(w.state.base_quat, c.state.base_quat, rtol=0, atol=1e-5)
    assert torch.allclose(w.state.joint_vel, c.state.joint_vel, rtol=0, atol=2e-4)
    assert torch.allclose(w.state.base_lin_vel, c.state.base_lin_vel, rtol=0, atol=2e-4)
    assert torch.allclose(w.state.base_ang_vel, c.state.base_ang_vel, rtol=0, atol=2e-4)
    assert torch.allclose(w.joint_torques, c.joint_torques, rtol=0, atol=1e-4)
    assert torch.allclose(w.foot_forces, c.foot_forces, rtol=0, atol=0.01)
    assert w.foot_forces.min() > 5  # the robot stood on all four feet through the step


@pytest.fixture(scope="module")
def warp3():
    sim = build("warp", 3)
    hold_default(sim, 0.2)
    return sim


def test_divergence_is_reported_not_raised(warp3):
    sim = warp3
    sim.reset(
        torch.arange(3), torch.tensor([[0.0, 0.0, 0.3]] * 3), torch.tensor([[1.0, 0, 0, 0]] * 3),
        torch.zeros(3, 3), torch.zeros(3, 3), sim.default_joint_pos.expand(3, -1), torch.zeros(3, 12),
    )
    before = sim.read_state()
    sim._qvel_t[1, :] = 1e12  # a blown-up state, as an unstable simulation produces
    sim._qpos_t[2, 8] = float("nan")
    result = sim.step(sim.default_joint_pos.expand(3, -1).clone(), SUBSTEPS)
    assert result.diverged.tolist() == [False, True, True]
    assert torch.isfinite(result.state.joint_vel).all() and torch.isfinite(result.foot_forces).all()
    assert torch.all(result.foot_forces[1:] == 0) and torch.all(result.joint_torques[1:] == 0)
    home = sim.default_joint_pos.expand(2, -1)
    assert torch.allclose(result.state.joint_pos[1:], home) and torch.all(result.state.joint_vel[1:] == 0)
    assert torch.allclose(result.state.base_pos[1:, 2], torch.tensor(0.35))  # back at the keyframe
    # The healthy env went on as if nothing happened elsewhere.
    assert (result.state.base_pos[0] - before.base_pos[0]).abs().max() < 0.01
    assert not hold_default(sim, 0.1)[-1].diverged.any()  # the batch goes on


def test_only_the_deliberate_line_search_cap_is_kept_quiet(warp3):
    import mujoco_warp as mjw

    flags = warp3.warp_model.opt.warn_overflow
    assert not flags & mjw.OverflowType.LS_ITERATIONS
    for kept in (mjw.OverflowType.NEFC, mjw.OverflowType.NARROWPHASE, mjw.OverflowType.ITERATIONS):
        assert flags & kept


def test_reset_writes_the_given_state(warp3):
    sim = warp3
    hold_default(sim, 0.1)
    ids = torch.tensor([0, 2])
    pos = torch.tensor([[0.0, 0.0, 0.5], [1.0, 2.0, 0.4]])
    quat = torch.tensor([[1.0, 0, 0, 0], [1.0, 0, 0, 0]])
    lin = torch.tensor([[0.3, 0, 0], [0, 0.2, 0]])
    joints = sim.default_joint_pos.expand(2, -1) + 0.1
    untouched = sim.read_state().base_pos[1].clone()
    sim.reset(ids, pos, quat, lin, torch.zeros(2, 3), joints, torch.zeros(2, 12))
    state = sim.read_state()
    assert torch.allclose(state.base_pos[ids], pos)
    assert torch.allclose(state.base_lin_vel[ids], lin)
    assert torch.allclose(state.joint_pos[ids], joints)
    assert torch.equal(state.base_pos[1], untouched)
    # The results are copies: stepping does not change a state already handed out.
    sim.step(sim.default_joint_pos.expand(3, -1).clone(), SUBSTEPS)
    assert torch.allclose(state.base_pos[ids], pos)
    # An MjData for rendering gets the env's current state.
    data = mujoco.MjData(sim.model)
    sim.copy_state_to(2, data)
    assert np.allclose(data.qpos[:3], sim.read_state().base_pos[2].numpy(), atol=1e-6)


def test_randomisation_is_per_env(warp3):
    sim = warp3
    sim.set_ground_friction(torch.tensor([0, 1]), torch.tensor([0.05, 1.0]))
    assert np.allclose(sim.ground_friction(), [0.05, 1.0, 1.0])
    sim.set_base_mass_offset(torch.tensor([1]), torch.tensor([0.5]))
    subtree = sim.warp_model.body_subtreemass.numpy()
    assert subtree[1, sim._base_body] == pytest.approx(sim.robot_mass + 0.5, rel=1e-5)
    assert subtree[0, sim._base_body] == pytest.approx(sim.robot_mass, rel=1e-5)
    sim.set_base_com_offset(torch.tensor([2]), torch.tensor([[0.02, 0.0, 0.0]]))
    ipos = sim.warp_model.body_ipos.numpy()[:, sim._base_body]
    assert np.allclose(ipos[:, 0], [0.0, 0.0, 0.02])
    result = hold_default(sim, 1.0)[-1]
    weights = result.foot_forces[:, -1].sum(dim=-1)
    assert weights[1] > weights[0] + 0.25 * sim.gravity  # the extra 0.5 kg shows in the feet
    # Friction: a push slides the robot on the slippery floor further than on the normal one.
    sim.push_base(torch.tensor([0, 2]), torch.tensor([[1.5, 0.0], [1.5, 0.0]]))
    start = sim.read_state().base_pos[:, 0].clone()
    hold_default(sim, 0.5)
    travelled = sim.read_state().base_pos[:, 0] - start
    assert travelled[0] > travelled[2] + 0.05


def test_wrong_control_shape_is_named(warp3):
    with pytest.raises(ValueError, match=r"shape \(3, 12\).*got \(3, 11\)"):
        warp3.step(torch.zeros(3, 11), SUBSTEPS)


def test_status_line_says_graphs_are_off_on_the_cpu_and_when_they_would_run(capsys):
    sim = build("warp", 1)
    line = capsys.readouterr().out.splitlines()[0]
    assert line == sim.graph_status
    assert line == ("warp on cpu: CUDA graphs off (Warp's CPU device; a CUDA device would use them given "
                    "driver >= 12.4 and Warp's memory pool)")


@pytest.mark.parametrize("driver, mempool, requested, on, why", [
    ((12, 8), True, True, True, "driver 12.8, memory pool on"),
    ((12, 2), True, True, False, "driver 12.2; graphs need driver >= 12.4"),
    (None, False, True, False, "no CUDA driver version, memory pool off; graphs need"),
    ((12, 2), False, False, False, "eager by request: sim.cuda_graphs=false"),
])
def test_graph_decision_on_cuda_names_what_is_missing(driver, mempool, requested, on, why):
    from gym_envs.sim.mujoco_warp import graph_decision

    use, reason = graph_decision(True, driver, mempool, requested)
    assert use is on and reason.startswith(why)
