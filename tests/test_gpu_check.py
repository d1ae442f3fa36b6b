"""tools/gpu_check.py as CI's smoke test: every step on Warp's CPU device with tiny sizes, into one log."""

import pytest

pytest.importorskip("mujoco_warp")

from tools import gpu_check  # noqa: E402


def test_every_step_runs_and_lands_in_one_log(tmp_path):
    log = tmp_path / "gpu_check.log"
    status = gpu_check.main([
        "--device", "cpu", "--num_envs", "2", "--steps", "2", "--rounds", "1",
        "--train_minutes", "3", "--train_num_envs", "2", "--train_max_iterations", "1",
        "--log_root", str(tmp_path / "logs"), "--log", str(log),
    ])
    text = log.read_text()
    assert status == 0, text
    assert "warp on cpu: CUDA graphs off (Warp's CPU device" in text.splitlines()[1]
    for check in ("standing foot forces", "one step: joint_pos", "one step: foot_forces", "divergence rescue",
                  "training"):
        assert f"PASS {check}:" in text
    assert any(line.split()[:1] == ["2"] for line in text.splitlines())  # the throughput row of 2 robots
    assert list((tmp_path / "logs").rglob("model_*.pt"))  # the training run saved its checkpoint
