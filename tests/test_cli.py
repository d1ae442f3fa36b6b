"""train.py and play.py end to end: mostly in-process through main(argv), two checks in subprocesses."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import torch

import play
import train
from learning import runs

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FAST = ["--num_envs", "32", "--num_threads", "1", "--set", "train.num_steps_per_env=8"]


def run_train(root, *args):
    return train.main(["--task", "mini_cheetah_osc", "--log_root", str(root), "--headless", *FAST, *args])


def only_run(root, experiment="ORC_111"):
    (name,) = os.listdir(os.path.join(root, experiment))
    return os.path.join(root, experiment, name)


def snapshot(root):
    """Every file under root with its size and mtime: to show nothing was written or replaced."""
    out = {}
    for dirpath, _, files in os.walk(root):
        for f in files:
            st = os.stat(os.path.join(dirpath, f))
            out[os.path.join(dirpath, f)] = (st.st_size, st.st_mtime_ns)
    return out


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """One 2-iteration run of 32 envs, shared by the tests that only read it."""
    root = tmp_path_factory.mktemp("logs")
    assert run_train(root, "--max_iterations", "2", "--seed", "1") == 0
    return root, only_run(root)


def test_training_writes_configs_checkpoints_and_events(trained):
    root, run = trained
    files = os.listdir(run)
    assert {"env.yaml", "train.yaml", "model_0.pt", "model_2.pt"} <= set(files)
    assert any(f.startswith("events.out.tfevents") for f in files)
    assert os.path.basename(run).endswith("_seed1")
    text = open(os.path.join(run, "train.yaml")).read()
    assert "task: mini_cheetah_osc" in text and "seed: 1" in text and "num_steps_per_env: 8" in text
    env_text = open(os.path.join(run, "env.yaml")).read()
    assert "num_envs: 32" in env_text and "seed: 1" in env_text and "orc: '111'" in env_text
    assert torch.load(os.path.join(run, "model_2.pt"), weights_only=True)["iter"] == 2


def _scalars(run_dir, tag):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(run_dir)
    acc.Reload()
    return [e.step for e in acc.Scalars(tag)]


def test_resume_continues_the_iteration_count_in_a_new_run(trained, tmp_path, capsys):
    root, run = trained
    before = snapshot(root)
    assert train.main(["--resume", "--load_run", run, "--log_root", str(tmp_path), "--max_iterations", "2",
                       "--num_threads", "1"]) == 0
    assert re.search(r"\bit 3/4 ", capsys.readouterr().out)
    assert snapshot(root) == before  # the resumed run is left alone
    new = only_run(tmp_path)
    assert runs.list_checkpoints(new) == [4]
    assert torch.load(os.path.join(new, "model_4.pt"), weights_only=True)["iter"] == 4
    assert f"resumed_from: {os.path.join(run, 'model_2.pt')}" in open(os.path.join(new, "train.yaml")).read()
    assert _scalars(run, "Loss/value") == [0, 1]
    assert _scalars(new, "Loss/value") == [2, 3]
    assert _scalars(new, "Perf/env_steps_per_s") == [2, 3]


def test_a_resumed_run_continues_its_reward_schedule_where_the_checkpoint_left_it(trained, tmp_path, capsys):
    from learning import launch

    _, run = trained  # two iterations of 8 steps per robot
    for start_step, stage in ((16, 2), (17, 1)):
        stage_overrides = [f"rewards.second_stage.start_step={start_step}", "rewards.second_stage.weights={swing_grf: 9.0}"]
        plan = launch.resolve(launch.RunRequest(resume=True, load_run=run, log_root=str(tmp_path / str(start_step)),
                                                max_iterations=1, num_threads=1, overrides=stage_overrides))
        runner, _, lock = launch.start_run(plan)
        lock.release()
        task = runner.env.task
        assert (task.common_step_counter, task.reward_stage) == (16, stage)
        assert task.reward_weights["swing_grf"] == (9.0 if stage == 2 else 5.0)
    # cpu_oscillators stages no weights of its own (cpu_envelope, the CPU default, does)
    assert run_train(tmp_path / "new", "--max_iterations", "1", "--profile", "cpu_oscillators", "--set",
                     "rewards.second_stage.start_step=20") == 0
    assert "second stage from iteration 3: rewards: no change" in capsys.readouterr().out


def test_a_resume_that_sets_the_learning_rate_trains_at_it(trained, tmp_path):
    from learning import launch

    _, run = trained
    saved = torch.load(os.path.join(run, "model_2.pt"), weights_only=True)["optimizer_state_dict"]
    adapted = saved["param_groups"][0]["lr"]  # the adaptive schedule moved it off 1e-3 in two iterations
    for overrides, rate in (([], adapted), (["train.algorithm.learning_rate=3e-5"], 3e-5)):
        plan = launch.resolve(launch.RunRequest(resume=True, load_run=run, log_root=str(tmp_path / str(rate)),
                                                max_iterations=1, num_threads=1,
                                                overrides=["train.algorithm.schedule=fixed", *overrides]))
        runner, _, lock = launch.start_run(plan)
        runner.learn(1, False)
        lock.release()
        assert [g["lr"] for g in runner.alg.optimizer.param_groups] == [rate] and runner.alg.learning_rate == rate
    assert adapted != 1e-3


def test_same_seed_same_weights_other_seed_other_weights(trained, tmp_path):
    _, run = trained
    assert run_train(tmp_path, "--max_iterations", "2", "--seed", "1") == 0
    a = torch.load(os.path.join(run, "model_2.pt"), weights_only=True)
    b = torch.load(os.path.join(only_run(tmp_path), "model_2.pt"), weights_only=True)
    for part in ("actor_state_dict", "critic_state_dict"):
        assert a[part].keys() == b[part].keys()
        for key in a[part]:
            assert torch.equal(a[part][key], b[part][key]), key
    initial = torch.load(os.path.join(run, "model_0.pt"), weights_only=True)
    assert not torch.equal(a["actor_state_dict"]["mlp.0.weight"], initial["actor_state_dict"]["mlp.0.weight"])
    other_root = tmp_path / "other_seed"
    assert run_train(other_root, "--max_iterations", "1", "--seed", "2") == 0
    other = torch.load(os.path.join(only_run(other_root), "model_0.pt"), weights_only=True)
    assert not torch.equal(other["actor_state_dict"]["mlp.0.weight"], initial["actor_state_dict"]["mlp.0.weight"])


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_play_exports_torchscript_onnx_and_controller_that_agree(trained, capsys):
    import onnxruntime

    root, run = trained
    assert play.main(["--log_root", str(root), "--headless", "--export", "--num_envs", "4", "--duration", "0.2",
                      "--num_threads", "1", "--command", "1.0", "--osc_init", "trot", "--coupling", "off"]) == 0
    out = capsys.readouterr().out
    assert "mean forward velocity" in out
    jit_path, onnx_path = (os.path.join(run, "exported", f) for f in ("policy.pt", "policy.onnx"))
    assert sorted(os.listdir(os.path.join(run, "exported"))) == ["controller.onnx", "policy.onnx", "policy.pt"]

    session = play.Session(play.build_parser().parse_args(["--load_run", run, "--num_envs", "2", "--log_root",
                                                             str(root)]))
    obs = torch.randn(5, 53) * 2
    with torch.inference_mode():
        from tensordict import TensorDict

        reference = session.policy(TensorDict({"actor": obs, "critic": torch.zeros(5, 61)}, batch_size=[5])).numpy()
    jit = torch.jit.load(jit_path)
    np.testing.assert_allclose(jit(obs).detach().numpy(), reference, atol=1e-5, rtol=0)
    sess = onnxruntime.InferenceSession(onnx_path)
    name = sess.get_inputs()[0].name
    onnx_out = np.concatenate([sess.run(None, {name: obs[i : i + 1].numpy()})[0] for i in range(5)])
    np.testing.assert_allclose(onnx_out, reference, atol=1e-5, rtol=0)


def test_play_evaluation_settings(trained):
    root, run = trained
    args = play.build_parser().parse_args(["--load_run", run, "--log_root", str(root), "--num_envs", "3",
                                           "--command", "2", "0.5", "-1", "--coupling", "off"])
    session = play.Session(args)
    cfg = session.task.cfg
    assert cfg.observations.noise_scale == 0 and cfg.osc.process_noise_std == 0 and cfg.osc.omega_noise_std == 0
    assert not cfg.push.enabled and not cfg.domain_rand.randomize_friction and cfg.osc.coupling_max == 0
    assert cfg.osc.orc == "111" and session.task.max_episode_length > 10**6
    assert torch.equal(session.task.commands, torch.tensor([[2.0, 0.5, -1.0]] * 3))


def test_a_run_trained_with_warp_on_a_gpu_plays_and_is_analysed_on_the_cpu_backend(trained, tmp_path):
    """A GPU run records env.device cuda:0 and sim.backend warp; a laptop without CUDA (or the gpu extra) still
    plays and analyses it, on mujoco.batch. Before, analysis asked torch for a CUDA generator and failed."""
    import shutil

    import yaml

    from analysis.locomotion import check_locomotion
    from analysis.rollout import load_policy_run
    from gym_envs.sim.mujoco_batch import MujocoBatchBackend

    root, run = trained
    gpu_run = str(tmp_path / "gpu_run")
    shutil.copytree(run, gpu_run, ignore=shutil.ignore_patterns(".lock"))
    env_yaml = os.path.join(gpu_run, "env.yaml")
    data = yaml.safe_load(open(env_yaml))
    data["env"]["device"], data["sim"]["backend"] = "cuda:0", "warp"
    yaml.safe_dump(data, open(env_yaml, "w"), sort_keys=False)

    args = play.build_parser().parse_args(["--load_run", gpu_run, "--num_envs", "2", "--num_threads", "1"])
    session = play.Session(args)
    assert isinstance(session.task.sim, MujocoBatchBackend) and session.task.device == torch.device("cpu")

    policy = load_policy_run(gpu_run)
    assert (policy.env_cfg.env.device, policy.env_cfg.sim.backend) == ("cuda:0", "warp")  # as trained
    check = check_locomotion(policy.policy, policy.env_cfg, warmup_s=0.1, measure_s=5.0, num_envs=2, num_threads=1)
    assert check.num_envs == 2 and np.isfinite(check.mean_velocity)


def _assert_one_line_error(capsys, code, pattern):
    err = capsys.readouterr().err.strip()
    assert code in (1, 2)  # 2: a malformed flag, caught by the parser
    assert "\n" not in err, err
    assert re.search(pattern, err), err


@pytest.mark.parametrize(
    "argv, pattern",
    [
        (["--task", "nope"], r"^train\.py: error: unknown task 'nope'"),
        (["--task", "mini_cheetah_osc", "--orc", "12"], r"argument --orc: '12' is not an ORC string"),
        (["--task", "mini_cheetah_osc", "--set", "env.num_env=3"], r"did you mean 'env.num_envs'"),
        (["--task", "mini_cheetah_osc", "--set", "train.algorithm.lr=3"], r"unknown config key 'algorithm.lr'"),
        (["--task", "mini_cheetah_osc", "--set", "algorithm.gamma=0.9"], r"prefix it with 'train.'"),
        (["--resume", "--load_run", "missing_run"], r"no run 'missing_run' under .* existing runs: ORC_111/"),
        (["--resume", "--checkpoint", "7"], r"has no checkpoint 7; available iterations: 0, 2"),
        (["--resume", "--load_run", "RUN"], r"model_2.pt is at iteration 2, the run's planned total "
                                           r"\(train.max_iterations 2\); add --max_iterations N to train N more"),
        (["--task", "mini_cheetah_osc", "--set", "train.save_interval=0"],
         r"config key 'train.save_interval' is 0; allowed: a number >= 1"),
        (["--resume", "--orc", "011", "--load_run", "RUN", "--max_iterations", "9"],
         r"expects 53 actor / 61 critic observations but .* gives 45 / 49; likely cause: the ORC O-bit differs"),
    ],
)
def test_train_bad_inputs(trained, capsys, argv, pattern):
    root, run = trained
    argv = [run if a == "RUN" else a for a in argv]
    before = snapshot(root)
    code = train.main([*argv, "--log_root", str(root), "--num_threads", "1"])
    _assert_one_line_error(capsys, code, pattern)
    assert snapshot(root) == before
    assert os.listdir(root) == ["ORC_111"] and len(os.listdir(os.path.join(root, "ORC_111"))) == 1


@pytest.mark.parametrize(
    "argv, pattern",
    [
        (["--task", "nope"], r"^play\.py: error: .*task=nope"),
        (["--load_run", "missing_run"], r"no run 'missing_run'"),
        (["--checkpoint", "99"], r"has no checkpoint 99; available iterations: 0, 2"),
        (["--set", "osc.coupling_mx=0"], r"did you mean 'osc.coupling_max'"),
        (["--orc", "011", "--load_run", "RUN"], r"expects 53 actor .* gives 45 / 49; likely cause: the ORC O-bit"),
    ],
)
def test_play_bad_inputs(trained, capsys, argv, pattern):
    root, run = trained
    argv = [run if a == "RUN" else a for a in argv]
    before = snapshot(root)
    code = play.main([*argv, "--log_root", str(root), "--headless", "--export", "--num_envs", "2"])
    _assert_one_line_error(capsys, code, pattern)
    assert snapshot(root) == before


def test_play_without_runs_or_shipped_policy_is_one_line(trained, capsys, monkeypatch, tmp_path):
    root, _ = trained
    monkeypatch.setattr(runs, "POLICY_ROOT", str(tmp_path / "no_policies"))
    code = play.main(["--orc", "010", "--log_root", str(root), "--headless", "--num_envs", "2"])
    _assert_one_line_error(capsys, code, r"no run with a checkpoint .* orc=010.* no shipped policy at .*ORC_010")


def test_play_falls_back_to_the_shipped_policy(tmp_path, capsys):
    code = play.main(["--task", "mini_cheetah_osc", "--orc", "010", "--log_root", str(tmp_path), "--headless",
                      "--num_envs", "2", "--duration", "0.2", "--num_threads", "1"])
    assert code == 0
    assert os.path.join("resources", "policies", "ORC_010", "seed0") in capsys.readouterr().out


@pytest.mark.parametrize("signum, status", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_ctrl_c_or_sigterm_saves_a_checkpoint_and_exits_128_plus_the_signal(tmp_path, signum, status):
    """SIGTERM is what SLURM and Kubernetes send before SIGKILL: it must save like Ctrl-C."""
    cmd = [sys.executable, "-u", "train.py", "--task", "mini_cheetah_osc", "--log_root", str(tmp_path),
           "--max_iterations", "1000", "--num_envs", "16", "--num_threads", "1", "--set", "train.num_steps_per_env=4"]
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines = []
    for line in proc.stdout:
        lines.append(line)
        if re.search(r"\bit +3/1000", line):
            proc.send_signal(signum)
            break
    out = "".join(lines) + proc.communicate(timeout=60)[0]
    assert proc.returncode == status, out
    run = only_run(tmp_path)
    last = runs.list_checkpoints(run)[-1]
    assert last >= 3 and f"stopped at iteration {last}" in out  # the last completed iteration, not save_interval's
    assert torch.load(runs.checkpoint_path(run, last), weights_only=True)["iter"] == last
    assert not [f for f in os.listdir(run) if f.endswith(".tmp")]


def test_play_video_headless(trained, tmp_path):
    root, _ = trained
    video = tmp_path / "robot0.mp4"
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    proc = subprocess.run(
        [sys.executable, "play.py", "--log_root", str(root), "--headless", "--num_envs", "2", "--duration", "0.3",
         "--num_threads", "1", "--video", str(video)],
        cwd=REPO, capture_output=True, text=True, env=env, timeout=120,
    )
    if proc.returncode and "offscreen rendering failed" in proc.stderr:
        pytest.skip(proc.stderr.strip())
    assert proc.returncode == 0, proc.stderr
    assert "video" in proc.stdout and video.stat().st_size > 0


def test_a_second_ctrl_c_exits_quietly(tmp_path, capsys, monkeypatch):
    from learning.vec_env import TaskVecEnv

    step, calls = TaskVecEnv.step, []

    def step_then_two_ctrl_c(self, actions):
        calls.append(1)
        if len(calls) == 5:  # inside the second iteration's rollout
            signal.raise_signal(signal.SIGINT)
            signal.raise_signal(signal.SIGINT)
        return step(self, actions)

    monkeypatch.setattr(TaskVecEnv, "step", step_then_two_ctrl_c)
    assert run_train(tmp_path, "--max_iterations", "100", "--set", "train.num_steps_per_env=4") == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["train.py: interrupted; stopped without saving"]
    assert runs.list_checkpoints(only_run(tmp_path)) == [0]  # the first Ctrl-C's save was aborted by the second


def test_sigkill_during_saves_leaves_loadable_checkpoints_and_resume_cleans_up(tmp_path, capsys):
    """Fault injection: kill -9 the moment a checkpoint is being written (every iteration saves). The child's
    torch.save lingers 0.5 s after writing, inside the save, so the kill lands there on a busy machine too."""
    slow_save = ("import runpy, sys, time, torch\n"
                 "save = torch.save\n"
                 "def lingering_save(obj, f, *args, **kwargs):\n"
                 "    save(obj, f, *args, **kwargs); f.flush(); time.sleep(0.5)\n"
                 "torch.save = lingering_save\n"
                 "sys.argv[0] = 'train.py'\n"
                 "runpy.run_path('train.py', run_name='__main__')\n")
    cmd = [sys.executable, "-c", slow_save, "--task", "mini_cheetah_osc", "--log_root", str(tmp_path), "--seed", "4",
           "--max_iterations", "100000", "--num_envs", "4", "--num_threads", "1", "--set", "train.num_steps_per_env=2",
           "--set", "train.save_interval=1", "--set", "train.algorithm.num_mini_batches=1"]
    left = []
    for attempt in range(4):  # should the kill still land after a rename, try again
        proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 60
        while proc.poll() is None and time.monotonic() < deadline:
            run = os.path.join(tmp_path, "ORC_111", sorted(os.listdir(tmp_path / "ORC_111"))[-1]) \
                if (tmp_path / "ORC_111").is_dir() and os.listdir(tmp_path / "ORC_111") else None
            names = os.listdir(run) if run else []
            if len(runs.list_checkpoints(run) if run else []) >= 3 and any(n.endswith(".tmp") for n in names):
                break
        proc.kill()  # inside a save, or (on a slow machine) at the deadline: then this attempt does not count
        proc.wait(timeout=30)
        left = [n for n in os.listdir(run) if n.endswith(".tmp")] if run else []
        if left:
            break
        cmd += ["--run_name", f"attempt{attempt + 1}"]
    assert left, "no kill landed inside a save in 4 attempts"
    checkpoints = runs.list_checkpoints(run)
    for it in checkpoints:
        assert runs.load_checkpoint(runs.checkpoint_path(run, it))["iter"] == it
    assert train.main(["--resume", "--load_run", run, "--log_root", str(tmp_path / "resumed"), "--max_iterations",
                       "1", "--num_threads", "1"]) == 0
    assert not [n for n in os.listdir(run) if n.endswith(".tmp")]  # removed at the start of the resume
    assert runs.list_checkpoints(only_run(tmp_path / "resumed")) == [checkpoints[-1] + 1]


def test_play_names_the_policy_and_how_to_choose_the_shipped_one(trained, capsys):
    root, run = trained
    assert play.main(["--orc", "111", "--log_root", str(root), "--headless", "--num_envs", "2", "--duration", "0.05",
                      "--num_threads", "1"]) == 0
    out = capsys.readouterr().out
    assert f"policy {os.path.join(run, 'model_2.pt')} (iteration 2; the newest run of ORC 111 under {root})" in out
    assert "the shipped one: --shipped --orc 111" in out


def test_the_shipped_policy_plays_on_request_and_exports_into_the_log_root(trained, tmp_path, capsys):
    root, _ = trained
    before = snapshot(runs.POLICY_ROOT)
    assert play.main(["--shipped", "--orc", "110", "--log_root", str(tmp_path), "--headless", "--num_envs", "2",
                      "--duration", "0.05", "--num_threads", "1", "--export"]) == 0
    shipped_iteration = max(runs.list_checkpoints(runs.shipped_policy_dir("110")))
    assert f"(iteration {shipped_iteration}; the shipped ORC 110 policy)" in capsys.readouterr().out
    assert {"policy.onnx", "policy.pt"} <= set(os.listdir(tmp_path / "shipped" / "ORC_110" / "seed0" / "exported"))
    assert snapshot(runs.POLICY_ROOT) == before  # resources/ untouched


def test_a_newer_run_that_cannot_be_read_is_named_not_skipped(trained, tmp_path, capsys):
    import shutil

    _, run = trained
    shutil.copytree(run, tmp_path / "ORC_111" / os.path.basename(run))
    broken = tmp_path / "ORC_111" / "2999-01-01_00-00-00_seed1"
    shutil.copytree(run, broken)
    (broken / "env.yaml").write_text("osc: [111\n")
    code = play.main(["--orc", "111", "--log_root", str(tmp_path), "--headless", "--num_envs", "2"])
    _assert_one_line_error(capsys, code, rf"the newest run {broken} cannot be read \(env.yaml: .*\); fix or remove "
                                         r"it, or choose a run with --load_run")


def test_print_config_shows_the_resolved_configs_as_set_keys_and_writes_nothing(trained, tmp_path, capsys):
    import yaml

    assert train.main(["--task", "mini_cheetah_osc", "--profile", "cpu_fast", "--num_envs", "64", "--log_root",
                       str(tmp_path), "--set", "train.save_interval=7", "--print_config"]) == 0
    data = yaml.safe_load(capsys.readouterr().out)
    assert data["env"]["num_envs"] == 64 and data["osc"]["orc"] == "111"
    assert data["train"]["save_interval"] == 7 and float(data["train"]["algorithm"]["learning_rate"]) == 1e-3
    assert data["train"]["actor"]["hidden_dims"] == [128, 128, 64]
    assert not os.listdir(tmp_path)
    root, _ = trained
    assert play.main(["--log_root", str(root), "--command", "1.5", "--print_config"]) == 0
    data = yaml.safe_load(capsys.readouterr().out)
    assert data["commands"]["lin_vel_x"] == [1.5, 1.5] and data["push"]["enabled"] is False
    assert data["train"]["num_steps_per_env"] == 8


def test_viewer_arrow_keys_turn_robot_0(monkeypatch, tmp_path, capsys):
    """The viewer's left arrow twice (+1 rad/s yaw) turns the shipped ORC-111's robot 0 by > 0.5 rad in 2 s."""
    import math

    import mujoco.viewer

    class Window:  # the passive viewer, offscreen: stays open, draws nothing
        def is_running(self):
            return True

        def sync(self):
            pass

        def close(self):
            pass

    monkeypatch.setattr(mujoco.viewer, "launch_passive", lambda *a, **k: Window())
    args = play.build_parser().parse_args(["--shipped", "--orc", "111", "--num_envs", "1", "--num_threads", "1",
                                           "--headless", "--log_root", str(tmp_path)])
    session = play.Session(args)
    viewer = play.Viewer(session, [1.0, 0.0, 0.0])
    viewer._key(play.KEY_LEFT)
    viewer._key(play.KEY_LEFT)
    obs = session.env.get_observations()

    def heading():
        w, x, y, z = session.task.state.base_quat[0].tolist()
        return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))

    turned, last = 0.0, None
    for _ in range(round(2.0 / session.env.dt)):
        viewer.update()
        with torch.inference_mode():
            obs, *_ = session.env.step(session.policy(obs))
        now = heading()
        if last is not None:
            turned += math.remainder(now - last, 2 * math.pi)
        last = now
    assert session.task.commands[0].tolist() == pytest.approx([1.0, 0.0, 1.0])
    assert "command: v_x +1.00  v_y +0.00  yaw +1.00" in capsys.readouterr().out
    assert turned > 0.5
