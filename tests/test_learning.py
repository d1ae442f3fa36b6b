"""Tests for learning/: train configs and their rsl-rl form, the VecEnv adapter, runs and checkpoints, the runner."""

from __future__ import annotations

import dataclasses
import os
import subprocess

import pytest
import torch

from gym_envs import env_cfg_class, make_env, oscillators
from gym_envs.mini_cheetah import MiniCheetahTrainCfg
from gym_envs.registry import TASKS, train_cfg_class
from gym_envs.train_config import TrainCfg
from gym_envs.config import ConfigError, load_yaml, save_yaml
from learning import runs
from learning.runner import StopRequest, TaskRunner
from learning.runner_config import PROFILES, apply_split_overrides, profile_overrides, split_overrides, to_rsl_rl_dict
from learning.vec_env import TaskVecEnv

TASK = "mini_cheetah_osc"


def small_env(num_envs=8, orc="111", task=TASK, **env):
    cfg = env_cfg_class(task)()
    cfg.env.num_envs = num_envs
    cfg.sim.num_threads = 1
    if hasattr(cfg, "osc"):
        cfg.osc.orc = orc
    for key, value in env.items():
        setattr(cfg.env, key, value)
    return TaskVecEnv(make_env(task, cfg))


def small_runner(env, log_dir=None, steps=4, **train):
    cfg = TrainCfg(task=TASK)
    cfg.num_steps_per_env = steps
    cfg.algorithm.num_mini_batches = 2
    for key, value in train.items():
        setattr(cfg, key, value)
    return TaskRunner(env, cfg, log_dir=log_dir)


@pytest.fixture(autouse=True)
def one_torch_thread():
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


# --- train configs ----------------------------------------------------------------------------


def test_osc_train_config_has_the_paper_values_in_rsl_rl_form():
    alg = TaskRunner(small_env(4), TrainCfg()).alg
    assert (alg.num_learning_epochs, alg.num_mini_batches, alg.clip_param) == (4, 8, 0.2)
    assert (alg.gamma, alg.lam, alg.entropy_coef, alg.value_loss_coef) == (0.99, 0.995, 0.02, 1.0)
    assert (alg.learning_rate, alg.schedule, alg.desired_kl, alg.max_grad_norm) == (1e-5, "adaptive", 0.01, 1.0)
    assert alg.use_clipped_value_loss and not alg.normalize_advantage_per_mini_batch
    for model, in_dim, out_dim in ((alg.actor, 53, 12), (alg.critic, 61, 1)):
        linear = [m for m in model.mlp if isinstance(m, torch.nn.Linear)]
        sizes = [(m.in_features, m.out_features) for m in linear]
        assert sizes == [(in_dim, 256), (256, 256), (256, 128), (128, out_dim)]
        assert any(isinstance(m, torch.nn.ELU) for m in model.mlp)
        assert model.obs_normalization
    assert alg.actor.distribution.std_type == "scalar"
    assert torch.equal(alg.actor.distribution.std_param.data, torch.ones(12))
    assert alg.critic.distribution is None


def test_parent_task_train_config_follows_facts_section_11():
    cfg = MiniCheetahTrainCfg()
    a = cfg.algorithm
    assert (cfg.num_steps_per_env, cfg.max_iterations) == (24, 1000)
    assert (a.learning_rate, a.num_learning_epochs, a.num_mini_batches) == (1e-4, 6, 6)
    assert (a.entropy_coef, a.gamma, a.lam, a.desired_kl, a.clip_param) == (0.01, 0.99, 0.99, 0.01, 0.2)
    assert cfg.actor.hidden_dims == cfg.critic.hidden_dims == (256, 256, 256)
    assert {"mini_cheetah", "mini_cheetah_osc"} <= set(TASKS) and train_cfg_class("mini_cheetah") is MiniCheetahTrainCfg
    with pytest.raises(ConfigError, match="unknown task 'x'"):
        train_cfg_class("x")


def test_rsl_rl_dict_is_fresh_and_complete():
    cfg = TrainCfg()
    d1, d2 = to_rsl_rl_dict(cfg), to_rsl_rl_dict(cfg)
    assert d1 == d2 and d1["actor"] is not d2["actor"]
    assert d1["obs_groups"] == {"actor": ["actor"], "critic": ["critic"]}
    assert (d1["num_steps_per_env"], d1["save_interval"]) == (32, 50)
    assert d1["actor"]["distribution_cfg"]["init_std"] == 1.0
    assert "distribution_cfg" not in d1["critic"]


def test_train_config_yaml_round_trip(tmp_path):
    for cls in {spec.train_cfg for spec in TASKS.values()}:
        path = tmp_path / f"{cls.__name__}.yaml"
        save_yaml(cls(), path)
        assert load_yaml(cls, path) == cls()


def test_every_profile_applies_to_every_task():
    for task in TASKS:
        for name, profile in PROFILES.items():
            if profile.tasks and task not in profile.tasks:
                with pytest.raises(ConfigError, match=f"profile '{name}' is for task"):
                    profile_overrides(name, task)
                continue
            apply_split_overrides(env_cfg_class(task)(), train_cfg_class(task)(), profile_overrides(name, task))
    env, train = apply_split_overrides(env_cfg_class(TASK)(), TrainCfg(), profile_overrides("cpu_fast"))
    assert env.env.num_envs == 1024 and train.num_steps_per_env == 24 and train.algorithm.learning_rate == 1e-3
    assert profile_overrides("paper") == []
    with pytest.raises(ConfigError, match="unknown profile 'nope'"):
        profile_overrides("nope")


def test_cpu_envelope_switches_stage_at_600_and_its_env_draws_the_stated_starts():
    env_cfg, train = apply_split_overrides(env_cfg_class(TASK)(), TrainCfg(), profile_overrides("cpu_envelope", TASK))
    stage, switch = env_cfg.rewards.second_stage, 600 * train.num_steps_per_env
    assert train.max_iterations == 1600  # E52's 1200 and 400 more, which ORC-110 needs for 3 m/s
    assert stage.start_step == env_cfg.osc.second_stage.start_step == switch  # iteration 600, halfway through E52
    assert stage.tracking_error == "absolute" and env_cfg.rewards.tracking_error == "relative"
    assert stage.weights == {"swing_grf": 10.0, "stance_grf": 10.0, "swing_contact": 5.0,
                             "tracking_lin_vel": 16.0, "tracking_ang_vel": 8.0} != {
        k: env_cfg.rewards.weights[k] for k in stage.weights}
    for term in ("tracking_lin_vel", "tracking_ang_vel"):  # both four times the first stage's
        assert stage.weights[term] == 4 * env_cfg.rewards.weights[term]
    assert list(train.actor.hidden_dims) == list(train.critic.hidden_dims) == [256, 256, 128]  # E50, E52
    # The profile builds; its uncoupled starts are a quarter, uniform over the gaits, then three-eighths
    # with bound drawn three times as often as each other gait.
    env_cfg.env.num_envs, env_cfg.sim.num_threads = 2048, 1
    env = make_env(TASK, env_cfg)
    for step, (share, bound) in ((0, (0.25, 0.25)), (switch, (0.375, 0.5))):
        env.continue_from_step(step)
        env.reset()
        uncoupled = env.coupling_on[:, 0] == 0
        assert uncoupled.float().mean().item() == pytest.approx(share, abs=0.04)
        labels, _ = oscillators.classify_rpd(oscillators.relative_phases(env.phase[uncoupled]))
        shares = torch.bincount(labels, minlength=len(oscillators.GAIT_NAMES) + 1).float() / len(labels)
        assert shares[oscillators.GAIT_NAMES.index("bound")].item() == pytest.approx(bound, abs=0.07)


def test_override_scheme_routes_train_prefix_and_catches_a_missing_prefix():
    assert split_overrides(["train.seed=3", "env.num_envs=2"]) == (["env.num_envs=2"], ["seed=3"])
    env, train = apply_split_overrides(
        env_cfg_class(TASK)(), TrainCfg(), ["osc.orc=010", "train.algorithm.learning_rate=1e-4"]
    )
    assert env.osc.orc == "010" and train.algorithm.learning_rate == 1e-4
    with pytest.raises(ConfigError, match="prefix it with 'train.'"):
        apply_split_overrides(env_cfg_class(TASK)(), TrainCfg(), ["algorithm.gamma=0.9"])
    with pytest.raises(ConfigError, match="did you mean 'algorithm.gamma'"):
        apply_split_overrides(env_cfg_class(TASK)(), TrainCfg(), ["train.algorithm.gamm=0.9"])


# --- VecEnv adapter ---------------------------------------------------------------------------


def test_vec_env_contract():
    env = small_env(6)
    obs = env.get_observations()
    assert obs["actor"].shape == (6, 53) and obs["critic"].shape == (6, 61)
    assert env.num_actions == 12 and env.max_episode_length == 400
    env.episode_length_buf = torch.full((6,), 399, dtype=torch.long)
    assert env.task.episode_length_buf is env.episode_length_buf
    for _ in range(2):
        obs, rewards, dones, extras = env.step(torch.zeros(6, 12))
    assert rewards.shape == (6,) and dones.shape == (6,)
    assert extras["time_outs"].all()  # counter 399 -> 401 > 400
    assert any(k.startswith("Episode_Reward/") for k in extras["log"])


# --- runs and checkpoints ---------------------------------------------------------------------


class NotAllowed:
    """Any class: what a weights_only load must refuse."""


def _fake_run(root, experiment, name, task=TASK, orc="111", checkpoints=(0,)):
    path = os.path.join(root, experiment, name)
    os.makedirs(path)
    env_cfg = env_cfg_class(task)()
    if hasattr(env_cfg, "osc"):
        env_cfg.osc.orc = orc
    save_yaml(env_cfg, os.path.join(path, runs.ENV_YAML))
    save_yaml(train_cfg_class(task)(task=task), os.path.join(path, runs.TRAIN_YAML))
    for it in checkpoints:
        open(runs.checkpoint_path(path, it), "wb").close()
    return path


def test_find_run_and_checkpoint(tmp_path):
    root = str(tmp_path)
    old = _fake_run(root, "ORC_111", "2024-01-01_00-00-00_a", checkpoints=(0, 9, 10))
    new = _fake_run(root, "ORC_110", "2024-02-01_00-00-00_b", orc="110")
    empty = _fake_run(root, "ORC_111", "2024-03-01_00-00-00_c", checkpoints=())
    parent = _fake_run(root, "mini_cheetah", "2024-01-15_00-00-00_d", task="mini_cheetah")
    assert runs.find_run(root) == new  # newest with a checkpoint; the empty run is skipped
    assert runs.find_run(root, orc="111") == old
    assert runs.find_run(root, task="mini_cheetah") == parent
    assert runs.find_run(root, "2024-01-01_00-00-00_a") == old
    assert runs.find_run(root, empty) == os.path.abspath(empty)
    with pytest.raises(runs.RunError, match="no run 'zzz' under .*existing runs: .*2024-02-01_00-00-00_b"):
        runs.find_run(root, "zzz")
    with pytest.raises(runs.RunError, match="for orc=000"):
        runs.find_run(root, orc="000")
    assert runs.find_checkpoint(old) == runs.checkpoint_path(old, 10)  # numeric, not lexicographic
    assert runs.find_checkpoint(old, 9) == runs.checkpoint_path(old, 9)
    with pytest.raises(runs.RunError, match="no checkpoint 5; available iterations: 0, 9, 10"):
        runs.find_checkpoint(old, 5)
    with pytest.raises(runs.RunError, match="has no checkpoints"):
        runs.find_checkpoint(empty)


def test_run_dirs_are_new_even_within_one_second(tmp_path):
    a = runs.create_run_dir(str(tmp_path), "exp", "seed0")
    b = runs.create_run_dir(str(tmp_path), "exp", "seed0")
    assert a != b and os.listdir(a) == os.listdir(b) == []
    assert os.path.basename(a).endswith("_seed0")


def test_checkpoints_are_atomic_weights_only_and_size_checked(tmp_path):
    env = small_env(4)
    runner = small_runner(env)
    path = str(tmp_path / "model_0.pt")
    runner.save(path)
    assert os.listdir(tmp_path) == ["model_0.pt"]  # no temporary file left behind
    data = torch.load(path, weights_only=True)
    assert data["iter"] == 0 and data["infos"] is None
    assert runs.model_io_dims(data["actor_state_dict"]) == (53, 12)

    other = small_runner(small_env(4, orc="011"))
    with pytest.raises(runs.RunError, match=r"expects 53 actor / 61 critic observations but .* gives 45 / 49; likely"):
        other.load(path, cause="x")
    bad = str(tmp_path / "model_1.pt")
    torch.save({"actor_state_dict": {}, "x": NotAllowed()}, bad)
    refusal = r"refused checkpoint .*model_1.pt: it holds tests.test_learning.NotAllowed, and loading it could run code"
    with pytest.raises(runs.RunError, match=refusal) as refused:
        runs.load_checkpoint(bad)
    assert "weights_only" not in str(refused.value)  # no advice to switch the protection off
    truncated = str(tmp_path / "model_2.pt")
    with open(path, "rb") as f, open(truncated, "wb") as g:
        g.write(f.read()[:1000])
    with pytest.raises(runs.RunError, match=r"cannot read checkpoint .*model_2.pt: .*failed finding central directory.*"
                                            r"saved properly"):  # torch's whole reason, not the first 200 characters
        runs.load_checkpoint(truncated)


def test_a_save_removes_the_temporary_files_of_interrupted_saves(tmp_path):
    stale = tmp_path / ".model_3.pt.x1y2.tmp"
    stale.write_bytes(b"half a checkpoint")
    small_runner(small_env(4)).save(str(tmp_path / "model_4.pt"))
    assert os.listdir(tmp_path) == ["model_4.pt"]


def test_a_checkpoint_with_other_hidden_sizes_is_one_line_naming_the_layer(tmp_path):
    path = str(tmp_path / "model_0.pt")
    small_runner(small_env(4)).save(path)
    narrow = small_runner(small_env(4), actor=dataclasses.replace(TrainCfg().actor, hidden_dims=(64, 32)))
    with pytest.raises(runs.RunError, match=r"actor layer mlp.0.weight is \[256, 53\] there but \[64, 53\] here; "
                                            r"likely cause: other train.actor.hidden_dims \(the checkpoint's: "
                                            r"\[256, 256, 128\], configured: \[64, 32\]\)"):
        narrow.load(path)


def test_learn_counts_completed_iterations_and_resumes_from_them(tmp_path):
    torch.manual_seed(0)
    env = small_env(8)
    runner = small_runner(env, log_dir=str(tmp_path), save_interval=2)
    assert runner.learn(3)
    assert runs.list_checkpoints(str(tmp_path)) == [0, 2, 3]
    assert torch.load(runs.checkpoint_path(str(tmp_path), 3), weights_only=True)["iter"] == 3
    resumed = small_runner(env)
    resumed.load(runs.checkpoint_path(str(tmp_path), 3))
    assert resumed.current_learning_iteration == 3
    for a, b in zip(resumed.alg.actor.state_dict().values(), runner.alg.actor.state_dict().values()):
        assert torch.equal(a, b)


def test_a_run_records_the_commit_it_was_trained_at(tmp_path):
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=runs.REPO_ROOT, capture_output=True,
                          text=True).stdout.strip()
    if not head:
        pytest.skip("not a git checkout")
    runner = small_runner(small_env(8), log_dir=str(tmp_path), save_interval=1)
    assert runner.learn(1)
    assert runs.trained_commit(str(tmp_path))[:7] == head[:7]
    assert runs.trained_commit(str(tmp_path / "nowhere")) is None


def test_trained_commit_marks_uncommitted_changes(tmp_path):
    (tmp_path / "git").mkdir()
    record = "--- git commit ---\n{}\n\n\n--- git status ---\nOn branch main\n\n\n--- git diff ---\n{}"
    (tmp_path / "git" / "repo.diff").write_text(record.format("924bf99c4fb920f3e6feb812f73b6e17a0c457fd", ""))
    assert runs.trained_commit(str(tmp_path)) == "924bf99"
    (tmp_path / "git" / "repo.diff").write_text(record.format("924bf99c4fb9", "+++ b/train.py\n+x = 1\n"))
    assert runs.trained_commit(str(tmp_path)) == "924bf99+diff"


def test_load_policy_gives_the_runners_deterministic_actor(tmp_path):
    torch.manual_seed(3)
    env = small_env(8)
    runner = small_runner(env, log_dir=str(tmp_path))
    save_yaml(env.task.cfg, tmp_path / runs.ENV_YAML)
    save_yaml(runner.train_cfg, tmp_path / runs.TRAIN_YAML)
    runner.learn(1)
    loaded = runs.load_policy(str(tmp_path))
    assert (loaded.task, loaded.iteration, loaded.env_cfg.osc.orc) == (TASK, 1, "111")
    obs = env.get_observations()
    expected = runner.get_inference_policy()(obs)
    assert torch.equal(loaded.policy(obs), expected)


def test_stop_request_drops_the_partial_rollout_and_saves_the_last_iteration(tmp_path):
    env = small_env(8)
    runner = small_runner(env, log_dir=str(tmp_path), steps=4)
    stop = StopRequest()
    step = env.step
    calls = []

    def counting_step(actions):
        calls.append(1)
        if len(calls) == 6:  # during the second rollout
            stop.requested = True
        return step(actions)

    env.step = counting_step
    assert runner.learn(10, stop=stop) is False
    assert runner.current_learning_iteration == 1
    assert runs.list_checkpoints(str(tmp_path)) == [0, 1]
    assert len(calls) == 6


def test_a_task_is_one_registry_entry(tmp_path, monkeypatch):
    """A newcomer's task: a class, its configs and one register() call; train.py then trains and names it."""
    import train
    from gym_envs.mini_cheetah import MiniCheetah, MiniCheetahCfg
    from gym_envs.registry import register

    class ToyCheetah(MiniCheetah):
        pass

    monkeypatch.setattr("gym_envs.registry.TASKS", dict(TASKS))
    register("toy_cheetah", ToyCheetah, MiniCheetahCfg, MiniCheetahTrainCfg)
    code = train.main(["--task", "toy_cheetah", "--device", "cpu", "--num_envs", "8", "--num_threads", "1",
                       "--max_iterations", "1", "--set", "train.num_steps_per_env=4", "--log_root", str(tmp_path)])
    assert code == 0
    (run,) = [os.path.join(tmp_path, "toy_cheetah", name) for name in os.listdir(tmp_path / "toy_cheetah")]
    assert runs.list_checkpoints(run) == [0, 1]
    task, _, train_cfg = runs.load_run_configs(run)
    assert (task, train_cfg.profile) == ("toy_cheetah", "cpu_fast")  # the registry entry's CPU recipe


def test_frozen_observation_normalisers_keep_their_statistics_from_the_set_iteration():
    torch.manual_seed(0)
    env = small_env(8)
    learning = small_runner(env)
    frozen = small_runner(env, obs_normalization_frozen_from=1)
    counts = {}
    for name, runner in (("learning", learning), ("frozen", frozen)):
        runner.learn(1)
        after_one = runner.alg.actor.obs_normalizer.count.item()
        mean_after_one = runner.alg.critic.obs_normalizer.mean
        runner.learn(2)
        counts[name] = (after_one, runner.alg.actor.obs_normalizer.count.item())
        if name == "frozen":
            assert torch.equal(runner.alg.critic.obs_normalizer.mean, mean_after_one)
    steps = 8 * 4  # robots x steps per iteration
    assert counts["learning"] == (steps, 3 * steps)
    assert counts["frozen"] == (steps, steps)
