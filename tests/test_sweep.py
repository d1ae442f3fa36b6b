"""sweep.py: every configuration and seed in its own folder, finished runs skipped, interrupted ones resumed."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys

import pytest
import torch

import sweep
from learning import runs
from tests.test_distributed import signal_at

TINY = ["--num_envs", "16", "--num_threads", "1", "--set", "train.num_steps_per_env=4", "--set", "env.episode_length_s=0.05"]


def run_sweep(out, *args):
    return sweep.main(["--out", str(out), "--orcs", "111", "010", "--seeds", "3", *TINY, *args])


def manifest(out):
    with open(os.path.join(out, "manifest.csv")) as f:
        return {(row["orc"], row["seed"]): row for row in csv.DictReader(f)}


def mtimes(folder):
    return {f: os.stat(os.path.join(folder, f)).st_mtime_ns for f in os.listdir(folder)}


def test_sweep_trains_skips_and_resumes(tmp_path):
    assert run_sweep(tmp_path, "--max_iterations", "1") == 0
    rows = manifest(tmp_path)
    assert set(rows) == {("111", "3"), ("010", "3")}
    for orc in ("111", "010"):
        run_dir = tmp_path / f"ORC_{orc}" / "seed3"
        assert {"env.yaml", "train.yaml", "model_0.pt", "model_1.pt"} <= set(os.listdir(run_dir))
        assert rows[(orc, "3")]["iterations"] == "1"
        assert float(rows[(orc, "3")]["wall_time_s"]) > 0
        assert rows[(orc, "3")]["final_reward"] != ""
    assert "orc: '010'" in (tmp_path / "ORC_010" / "seed3" / "env.yaml").read_text()

    # The same command again: both runs are finished, nothing is touched.
    before = mtimes(tmp_path / "ORC_111" / "seed3")
    assert run_sweep(tmp_path, "--max_iterations", "1") == 0
    assert mtimes(tmp_path / "ORC_111" / "seed3") == before

    # More iterations: each run continues in its own folder from its newest checkpoint.
    first_wall = float(manifest(tmp_path)[("111", "3")]["wall_time_s"])
    assert run_sweep(tmp_path, "--max_iterations", "2") == 0
    run_dir = tmp_path / "ORC_111" / "seed3"
    assert runs.list_checkpoints(str(run_dir)) == [0, 1, 2]
    assert torch.load(run_dir / "model_2.pt", weights_only=True)["iter"] == 2
    assert os.stat(run_dir / "model_1.pt").st_mtime_ns == before["model_1.pt"]  # kept as it was
    row = manifest(tmp_path)[("111", "3")]
    assert row["iterations"] == "2" and float(row["wall_time_s"]) > first_wall
    assert os.listdir(tmp_path / "ORC_111") == ["seed3"]  # no second folder for the resumed run

    # The runs' curves, read back from their event files (both tensorboard files of the resumed run).
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tools"))
    import plot_training_curves

    steps, rewards = plot_training_curves.curves(str(run_dir))["Train/mean_reward"]
    assert steps == [16 * 4]  # iteration 1; iteration 2 opens the resumed file's restart window (next test)
    assert plot_training_curves.main(["--runs", str(tmp_path), "--out", str(tmp_path / "curves.png")]) == 0
    assert (tmp_path / "curves.png").stat().st_size > 10_000


def test_resuming_with_other_settings_is_refused(tmp_path, capsys):
    assert sweep.main(["--out", str(tmp_path), "--orcs", "111", "--seeds", "0", *TINY, "--max_iterations", "1"]) == 0
    code = sweep.main(["--out", str(tmp_path), "--orcs", "111", "--seeds", "0", *TINY, "--max_iterations", "2",
                       "--set", "rewards.weights.torques=1e-6"])
    assert code == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "rewards.weights.torques differs" in err[0]
    assert runs.list_checkpoints(str(tmp_path / "ORC_111" / "seed0")) == [0, 1]
    # Another machine's thread count is not another experiment: the run continues.
    more_threads = list(TINY)
    more_threads[TINY.index("--num_threads") + 1] = "2"
    assert sweep.main(["--out", str(tmp_path), "--orcs", "111", "--seeds", "0", *more_threads,
                       "--max_iterations", "2"]) == 0
    assert runs.list_checkpoints(str(tmp_path / "ORC_111" / "seed0")) == [0, 1, 2]


@pytest.mark.parametrize("orc", ["12", "abc"])
def test_bad_orc_is_one_line(tmp_path, capsys, orc):
    assert sweep.main(["--out", str(tmp_path), "--orcs", orc]) == 2
    assert "is not an ORC string" in capsys.readouterr().err
    assert not os.listdir(tmp_path)


def test_sigterm_stops_the_sweep_with_a_checkpoint_and_the_next_sweep_resumes_it(tmp_path):
    repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    cmd = [sys.executable, "-u", "sweep.py", "--out", str(tmp_path), "--orcs", "111", "010", "--seeds", "3",
           "--max_iterations", "1000", *TINY]
    proc = subprocess.Popen(cmd, cwd=repo, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    out, _ = signal_at(proc, r"\bit +3/1000", signal.SIGTERM, timeout=60)
    assert proc.returncode == 143, out
    run_dir = str(tmp_path / "ORC_111" / "seed3")
    last = runs.list_checkpoints(run_dir)[-1]
    assert last >= 3 and "ORC 111 seed 3: stopped" in out and not (tmp_path / "ORC_010").exists()
    assert manifest(tmp_path)[("111", "3")]["iterations"] == str(last)
    assert sweep.main(["--out", str(tmp_path), "--orcs", "111", "--seeds", "3", "--max_iterations", str(last + 1),
                       *TINY]) == 0
    assert runs.list_checkpoints(run_dir)[-1] == last + 1


def test_num_threads_caps_torch_while_the_sweep_trains(tmp_path, monkeypatch):
    # Two sweeps side by side with --num_threads 1 must each run one busy torch thread, not one per core.
    from learning.runner import TaskRunner

    seen = []
    learn = TaskRunner.learn

    def spy(self, *args, **kwargs):
        seen.append(torch.get_num_threads())
        return learn(self, *args, **kwargs)

    monkeypatch.setattr(TaskRunner, "learn", spy)
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        assert sweep.main(["--out", str(tmp_path), "--orcs", "111", "--seeds", "0", *TINY, "--max_iterations", "1"]) == 0
        assert seen == [1] and torch.get_num_threads() == 2  # capped while training, restored after
    finally:
        torch.set_num_threads(before)


def test_training_curves_leave_out_a_resumed_runs_restart_window(tmp_path):
    """After a resume the episode statistics dip for one episode length (every robot restarts part-way through
    its episode): those iterations come from the earlier events file where it has them, else are left out."""
    from torch.utils.tensorboard import SummaryWriter

    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tools"))
    import plot_training_curves

    assert sweep.main(["--out", str(tmp_path), "--orcs", "111", "--seeds", "0", *TINY, "--max_iterations", "1"]) == 0
    run_dir = tmp_path / "ORC_111" / "seed0"
    for f in run_dir.glob("events.out.tfevents.*"):
        f.unlink()
    # 0.05 s episodes at 100 Hz are 5 control steps: a restart window of two iterations of 4 steps.
    for name, first, last, value in (("1.first", 0, 4, 1.0), ("2.resumed", 3, 9, 2.0)):
        with SummaryWriter(str(tmp_path / name)) as w:
            for step in range(first, last + 1):
                w.add_scalar("Train/mean_reward", value, step)
        (event,) = (tmp_path / name).glob("events.out.tfevents.*")
        event.rename(run_dir / f"events.out.tfevents.{name}")
    steps, rewards = plot_training_curves.curves(str(run_dir))["Train/mean_reward"]
    assert steps == [(s + 1) * 16 * 4 for s in range(10)]
    assert rewards == [1.0] * 5 + [2.0] * 5  # 3 and 4 from the first file, 5-9 from the resumed one
