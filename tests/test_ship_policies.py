"""tools/ship_policies.py: each seed of a sweep lands in its own folder, and shipping more seeds keeps the earlier ones."""

from __future__ import annotations

import csv
import os
import shutil
import sys

import pytest

import sweep
import train
from learning import runs

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tools"))
import ship_policies  # noqa: E402

from .test_sweep import TINY  # noqa: E402


@pytest.fixture(scope="module")
def sweep_runs(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep")
    assert sweep.main(["--out", str(out), "--orcs", "111", "--seeds", "3", "4", *TINY, "--max_iterations", "1"]) == 0
    return out


def manifest(out):
    with open(os.path.join(out, "manifest.csv"), newline="") as f:
        return [(row["orc"], row["seed"], row["iterations"], row["robots"]) for row in csv.DictReader(f)]


def test_seeds_ship_one_at_a_time_into_their_own_folders(sweep_runs, tmp_path, monkeypatch):
    measured = []

    def measure(policy_dir, num_threads):  # the rollouts are analysis's, tested there; here only what is shipped
        measured.append(policy_dir)
        return {key: len(measured) for key in ship_policies.METRICS}

    monkeypatch.setattr(ship_policies, "measure", measure)
    ship = ["--runs", str(sweep_runs), "--out", str(tmp_path), "--machine", "test"]
    assert ship_policies.main([*ship, "--seed", "4"]) == 0
    assert manifest(tmp_path) == [("111", "4", "1", "1")]
    assert ship_policies.main([*ship, "--seed", "3"]) == 0  # seed 4 stays shipped, seed 3 joins it
    assert manifest(tmp_path) == [("111", "3", "1", "2"), ("111", "4", "1", "1")]
    for seed in (3, 4):
        folder = runs.shipped_policy_dir("111", seed, str(tmp_path))
        assert sorted(os.listdir(folder)) == ["env.yaml", "model_1.pt", "train.yaml"]
        assert runs.load_run_configs(folder)[2].seed == seed
    assert ship_policies.main(["--remeasure", "--out", str(tmp_path)]) == 0
    assert measured[-2:] == [runs.shipped_policy_dir("111", s, str(tmp_path)) for s in (3, 4)]
    assert [row[:3] for row in manifest(tmp_path)] == [("111", "3", "1"), ("111", "4", "1")]


def only_run(root):
    (run,) = [os.path.join(d, n) for d, names, _ in os.walk(root) for n in names if runs.is_run_dir(os.path.join(d, n))]
    return run


def test_wall_time_of_a_resumed_run_counts_the_training_before_its_checkpoint(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    tiny = ["--num_threads", "1", "--headless"]
    assert train.main(["--task", "mini_cheetah_osc", "--log_root", str(tmp_path / "first"), "--max_iterations", "2",
                       "--num_envs", "16", "--set", "train.num_steps_per_env=4", *tiny]) == 0
    first = only_run(tmp_path / "first")
    assert train.main(["--resume", "--load_run", first, "--log_root", str(tmp_path / "resumed"), "--max_iterations",
                       "1", *tiny]) == 0
    resumed = only_run(tmp_path / "resumed")
    events = EventAccumulator(resumed)
    events.Reload()
    own = sum(e.value for tag in ("Perf/collection_time", "Perf/learning_time") for e in events.Scalars(tag))
    before = runs.training_seconds(first)
    assert 0 < runs.training_seconds(first, until=1) < before  # only iteration 0's events
    assert runs.training_seconds(resumed) == pytest.approx(own + before)
    shutil.rmtree(first)  # the run it was resumed from is gone: its time is unknown, not zero
    assert runs.training_seconds(resumed) is None


def test_a_shipped_policy_trained_on_carries_its_provenance(sweep_runs, tmp_path, monkeypatch):
    monkeypatch.setattr(ship_policies, "measure", lambda policy_dir, num_threads: {k: 0 for k in ship_policies.METRICS})
    out = str(tmp_path / "policies")
    assert ship_policies.main(["--runs", str(sweep_runs), "--out", out, "--seed", "3", "--machine", "first"]) == 0
    (first,) = ship_policies.read_manifest(out)
    shipped = runs.shipped_policy_dir("111", 3, out)
    assert train.main(["--resume", "--load_run", shipped, "--log_root", str(tmp_path / "longer"), "--max_iterations",
                       "1", "--num_threads", "1", "--headless"]) == 0
    longer = tmp_path / "continued" / "ORC_111" / "seed3"  # the layout ship_policies reads
    shutil.copytree(only_run(tmp_path / "longer"), longer)
    own = runs.training_seconds(str(longer), resumed_chain=False)
    assert ship_policies.main(["--runs", str(tmp_path / "continued"), "--out", out, "--machine", "second",
                               "--commit", "abc1234"]) == 0
    (row,) = ship_policies.read_manifest(out)
    assert row["iterations"] == "2" and os.listdir(shipped) and "model_2.pt" in os.listdir(shipped)
    assert float(row["wall_time_s"]) == pytest.approx(float(first["wall_time_s"]) + own, abs=0.1)
    assert row["commit"] == f"{first['commit']} then abc1234"
    assert row["machine"] == "iterations 1-1: first; 2-2: second"
