"""Left-right mirror maps (gym_envs.mirror), the task's maps checked against the simulator, and
training with rsl-rl's symmetry augmentation."""

from __future__ import annotations

import os

import numpy as np
import pytest
import torch
from tensordict import TensorDict

import train
from gym_envs import mirror
from gym_envs.config import ConfigError
from gym_envs.registry import env_cfg_class, make_env
from gym_envs.train_config import TrainCfg
from learning.runner_config import to_rsl_rl_dict
from learning.symmetry import mirror_augmentation
from learning.vec_env import TaskVecEnv

# A symmetric two-legged toy: hip abduction about x, hip flexion about y, per leg (right, left).
ANCHORS = np.array([[0.2, -0.1, 0.0], [0.2, -0.1, -0.05], [0.2, 0.1, 0.0], [0.2, 0.1, -0.05]])
AXES = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def test_joint_map_swaps_sides_and_flips_abduction_only():
    index, sign = mirror.joint_map(ANCHORS, AXES, np.zeros(4))
    assert index.tolist() == [2, 3, 0, 1] and sign.tolist() == [-1.0, 1.0, -1.0, 1.0]
    # A left joint whose axis is flipped in the model moves the other way for the same motion.
    flipped = AXES.copy()
    flipped[3] = -flipped[3]
    assert mirror.joint_map(ANCHORS, flipped, np.zeros(4))[1].tolist() == [-1.0, -1.0, -1.0, -1.0]


def test_a_map_applied_twice_is_the_identity():
    x = np.arange(1.0, 5.0)
    index, sign = mirror.joint_map(ANCHORS, AXES, np.zeros(4))
    assert np.array_equal((x[index] * sign)[index] * sign, x)


def test_an_asymmetric_model_or_home_pose_is_refused():
    moved = ANCHORS.copy()
    moved[2, 0] += 0.01
    with pytest.raises(mirror.AsymmetricModelError, match="joints of the model are not left-right symmetric"):
        mirror.joint_map(moved, AXES, np.zeros(4))
    # The same abduction angle on both sides tilts both legs one way; opposite angles are symmetric.
    with pytest.raises(mirror.AsymmetricModelError, match="home keyframe"):
        mirror.joint_map(ANCHORS, AXES, np.array([0.1, 0.0, 0.1, 0.0]))
    mirror.joint_map(ANCHORS, AXES, np.array([0.1, 0.0, -0.1, 0.0]))


def test_term_maps_and_their_concatenation():
    joints = mirror.joint_map(ANCHORS, AXES, np.zeros(4))
    legs = mirror.leg_map(ANCHORS[[0, 2]])
    assert mirror.term_map("axial", 3, joints, legs)[1].tolist() == [-1.0, 1.0, -1.0]
    index, sign = mirror.term_map("legs", 4, joints, legs)  # a cos block then a sin block
    assert index.tolist() == [1, 0, 3, 2] and sign.tolist() == [1.0] * 4
    index, sign = mirror.concatenate([mirror.term_map("command", 3, joints, legs), (index, sign)])
    assert index.tolist() == [0, 1, 2, 4, 3, 6, 5] and sign.tolist()[:3] == [1.0, -1.0, -1.0]
    with pytest.raises(ValueError, match="unknown mirror kind 'odd'"):
        mirror.term_map("odd", 3, joints, legs)
    with pytest.raises(ValueError, match="multiple of 2 entries, not 3"):
        mirror.term_map("legs", 3, joints, legs)


def _symmetric_test_env():
    """Two robots, every source of per-robot randomness off, so robot 1 can be robot 0's mirror image."""
    cfg = env_cfg_class("mini_cheetah_osc")()
    cfg.env.num_envs = 2
    cfg.init_state.lin_vel_x = (0.5, 0.5)
    cfg.init_state.lin_vel_z = (0.0, 0.0)
    cfg.init_state.haa_noise = 0.0
    cfg.domain_rand.randomize_friction = False
    cfg.push.enabled = False
    cfg.observations.noise_scale = 0.0
    cfg.osc.process_noise_std = cfg.osc.omega_noise_std = cfg.osc.coupling_noise_std = 0.0
    return make_env("mini_cheetah_osc", cfg)


def test_the_mirror_image_of_a_rollout_is_a_rollout_of_the_simulator():
    env = _symmetric_test_env()
    maps = env.mirror_maps()
    env.reset()
    legs, _ = mirror.leg_map(env.sim.foot_positions)
    assert legs.tolist() == [1, 0, 3, 2]  # RF <-> LF, RH <-> LH
    env.commands[:] = torch.tensor([[1.0, 0.3, 0.5], [1.0, -0.3, -0.5]])
    env.phase[1] = env.phase[0, torch.as_tensor(legs)]
    env.sim.push_base(torch.tensor([0, 1]), torch.tensor([[0.0, 0.4], [0.0, -0.4]]))
    generator = torch.Generator().manual_seed(0)
    index, sign = maps["actions"]
    for _ in range(40):
        action = 0.5 * torch.randn(env.num_actions, generator=generator)
        obs, *_ = env.step(torch.stack([action, action[index] * sign]))
    for group in ("actor", "critic"):
        group_index, group_sign = maps[group]
        assert (obs[group][0] - obs[group][1]).abs().max() > 1.0  # the two robots do move differently
        # Robots 0 and 1 are rows of one batch, which may round differently in the last bit (vector or
        # scalar loop, by processor). Measured: one float32 ulp added to every action of robot 1 at every
        # step moves these observations by at most 1e-6 after 40 steps; a wrong sign map by 8.9.
        torch.testing.assert_close(obs[group][1], obs[group][0][group_index] * group_sign, atol=1e-4, rtol=0)


def test_a_term_without_a_mirror_rule_is_named():
    env = _symmetric_test_env()
    env.OBS_MIRROR = {k: v for k, v in env.OBS_MIRROR.items() if k != "dof_vel"}
    with pytest.raises(ConfigError, match="observation term 'dof_vel' has no mirror rule; add it to"):
        env.mirror_maps()


def test_augmentation_appends_the_mirrored_batch():
    env = TaskVecEnv(_symmetric_test_env())
    obs = env.get_observations()
    actions = torch.randn(2, env.num_actions)
    both_obs, both_actions = mirror_augmentation(env, obs, actions)
    assert both_obs.batch_size[0] == 4 and both_actions.shape == (4, env.num_actions)
    index, sign = env.mirror_maps["actor"]
    torch.testing.assert_close(both_obs["actor"][2:], obs["actor"][:, index] * sign)
    twice, _ = mirror_augmentation(env, TensorDict({"actor": both_obs["actor"][2:]}, batch_size=[2]))
    torch.testing.assert_close(twice["actor"][2:], obs["actor"])
    assert mirror_augmentation(env, None, actions)[0] is None


def test_symmetry_reaches_rsl_rl_only_when_switched_on():
    cfg = TrainCfg()
    assert "symmetry_cfg" not in to_rsl_rl_dict(cfg)["algorithm"]
    cfg.algorithm.symmetry_cfg.use_mirror_loss = True
    cfg.algorithm.symmetry_cfg.mirror_loss_coeff = 0.5
    symmetry = to_rsl_rl_dict(cfg)["algorithm"]["symmetry_cfg"]
    assert symmetry["data_augmentation_func"] is mirror_augmentation and symmetry["mirror_loss_coeff"] == 0.5


def test_training_with_mirror_augmentation_and_loss(tmp_path):
    code = train.main(["--task", "mini_cheetah_osc", "--log_root", str(tmp_path), "--headless", "--num_envs", "16",
                       "--num_threads", "1", "--max_iterations", "2", "--set", "train.num_steps_per_env=4",
                       "--set", "train.algorithm.symmetry_cfg.use_data_augmentation=true",
                       "--set", "train.algorithm.symmetry_cfg.use_mirror_loss=true",
                       "--set", "train.algorithm.symmetry_cfg.mirror_loss_coeff=1.0"])
    assert code == 0
    (run,) = os.listdir(tmp_path / "ORC_111")
    files = os.listdir(tmp_path / "ORC_111" / run)
    assert "model_2.pt" in files
    assert "use_data_augmentation: true" in (tmp_path / "ORC_111" / run / "train.yaml").read_text()
