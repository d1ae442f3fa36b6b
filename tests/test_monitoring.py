"""--logger (rsl-rl's TensorBoard / W&B / Neptune writers) and --video clips during training, offline."""

from __future__ import annotations

import glob
import importlib.util
import os
import re
import subprocess
import sys
import time

import pytest
from rsl_rl.utils.utils import resolve_callable

import train
from gym_envs.config import ConfigError
from learning import video as video_module
from gym_envs.train_config import TrainCfg
from learning.runner_config import check_logger_ready, to_rsl_rl_dict
from learning.video import TrainingVideo

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TINY = ["--task", "mini_cheetah_osc", "--num_envs", "16", "--num_threads", "1", "--max_iterations", "3",
        "--set", "train.num_steps_per_env=8"]


def only_run(root):
    (run,) = glob.glob(os.path.join(str(root), "ORC_111", "*"))
    return run


@pytest.mark.parametrize("name, writer", [("wandb", "WandbLogWriter"), ("neptune", "NeptuneLogWriter")])
def test_logger_names_resolve_to_rsl_rls_writers(name, writer):
    cfg = TrainCfg(logger=name, log_project_name="gaits")
    entry = to_rsl_rl_dict(cfg)["logger"]
    assert entry == {"class_name": writer, "project_name": "gaits"}
    assert resolve_callable(entry["class_name"]).__module__.startswith("rsl_rl.utils.")
    assert to_rsl_rl_dict(TrainCfg())["logger"] == "tensorboard"


def _hide_package(monkeypatch, package):
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == package else real(name, *a))


@pytest.mark.parametrize("argv, pattern", [
    (["--logger", "neptune"], r'--logger neptune needs the neptune package: pip install -e "\.\[neptune\]"$'),
    (["--logger", "wandb"], r'--logger wandb needs the wandb package: pip install -e "\.\[wandb\]"$'),
    (["--set", "train.logger=mlflow"], r"config key 'train.logger' is 'mlflow'; allowed: one of tensorboard, wandb, "
                                       r"neptune$"),
])
def test_a_missing_logger_package_is_one_line_before_anything_is_written(argv, pattern, tmp_path, capsys,
                                                                          monkeypatch):
    _hide_package(monkeypatch, argv[1])
    assert train.main([*TINY, "--log_root", str(tmp_path), *argv]) == 1
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith("train.py: error: ")
    assert re.search(pattern, err), err
    assert os.listdir(tmp_path) == []


def test_neptune_credentials_are_checked_up_front(monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: object() if name == "neptune" else real(name, *a))
    cfg = TrainCfg(logger="neptune")
    with pytest.raises(ConfigError, match="needs NEPTUNE_API_TOKEN and NEPTUNE_USERNAME in the environment"):
        check_logger_ready(cfg, environ={})
    check_logger_ready(cfg, environ={"NEPTUNE_API_TOKEN": "t", "NEPTUNE_USERNAME": "u"})


class FakeRecorder:
    """Stands in for the renderer: writes one line per frame, so clips can be counted without OpenGL."""

    def __init__(self, sim, dt, path):
        self.path, self.frames = path, 0

    def capture(self, step):
        self.frames += 1

    def close(self):
        with open(self.path, "w") as f:
            f.write("frame\n" * self.frames)


def test_clips_start_every_n_iterations_last_their_length_and_appear_whole(tmp_path, monkeypatch):
    monkeypatch.setattr(video_module, "VideoRecorder", FakeRecorder)
    clips = TrainingVideo(sim=None, dt=0.01, interval=3, length_s=0.25)  # 25 steps
    clips.write_into(str(tmp_path))
    seen_during = []
    for it in range(8):  # 10 env steps per iteration
        clips.start_iteration(it)
        for _ in range(10):
            clips.after_step()
        seen_during.append(sorted(os.listdir(tmp_path / "videos")) if (tmp_path / "videos").exists() else [])
    last = clips.close()
    # iteration 0 starts a clip that ends within iteration 2; 3 is busy-free and starts the next; 6 the third,
    # cut short at the end (5 + 10 + ... steps) and kept.
    assert [os.path.basename(p) for p in clips.saved] == ["iter_000000.mp4", "iter_000003.mp4", "iter_000006.mp4"]
    assert seen_during[1] == [] and seen_during[2] == ["iter_000000.mp4"]  # never a partial file in the run
    assert (tmp_path / "videos" / "iter_000000.mp4").read_text().count("frame") == 25
    assert last == clips.saved[-1] and (tmp_path / "videos" / "iter_000006.mp4").read_text().count("frame") == 20
    assert not os.path.exists(clips.tmp_dir)


def test_wandb_offline_gets_scalars_config_and_the_training_clips(tmp_path, monkeypatch, capsys):
    pytest.importorskip("wandb")
    monkeypatch.setenv("WANDB_MODE", "offline")
    monkeypatch.setenv("WANDB_DIR", str(tmp_path))
    monkeypatch.setenv("WANDB_SILENT", "true")
    code = train.main([*TINY, "--log_root", str(tmp_path / "logs"), "--logger", "wandb",
                       "--log_project_name", "orcgym-test", "--video", "2", "--video_length", "0.1"])
    err = capsys.readouterr().err
    if code == 1 and "offscreen rendering failed" in err:
        pytest.skip(err.strip())
    assert code == 0, err
    run = only_run(tmp_path / "logs")
    assert sorted(os.listdir(os.path.join(run, "videos"))) == ["iter_000000.mp4", "iter_000002.mp4"]
    assert all(os.path.getsize(os.path.join(run, "videos", f)) > 1000 for f in os.listdir(os.path.join(run, "videos")))
    (offline,) = glob.glob(str(tmp_path / "wandb" / "offline-run-*"))
    deadline = time.monotonic() + 30  # wandb's service process may still be writing the offline record
    while True:
        record = open(glob.glob(os.path.join(offline, "run-*.wandb"))[0], "rb").read()
        clips = glob.glob(os.path.join(offline, "files", "media", "videos", "*.mp4"))
        if (b"Perf/env_steps_per_s" in record and len(clips) == 2) or time.monotonic() > deadline:
            break
        time.sleep(0.5)
    assert b"Loss/value" in record and b"Perf/env_steps_per_s" in record and b"train_cfg" in record
    assert len(clips) == 2
    assert {"model_0.pt", "model_3.pt"} <= set(os.listdir(os.path.join(offline, "files")))


def test_video_without_working_offscreen_gl_is_one_line_before_anything_is_written(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["MUJOCO_GL"] = "osmesa"
    proc = subprocess.run([sys.executable, "train.py", *TINY, "--log_root", str(tmp_path), "--video", "1"],
                          cwd=REPO, capture_output=True, text=True, env=env, timeout=120)
    if proc.returncode == 0:
        pytest.skip("OSMesa renders on this machine")
    assert proc.returncode == 1, proc.stderr
    err = proc.stderr.strip()
    # Where libOSMesa is installed but cannot render, the renderer fails; where it is missing, importing mujoco does.
    failure = ("offscreen rendering failed with MUJOCO_GL=osmesa", "cannot load the OpenGL backend MUJOCO_GL=osmesa")
    assert "\n" not in err and any(text in err for text in failure) and "MUJOCO_GL=egl" in err, err
    assert os.listdir(tmp_path) == []
