"""Defaults that fit the machine: the choice is pure, so CUDA and Warp are passed in, not needed."""

from __future__ import annotations

import os
import re

import pytest

import train
from learning import launch
from learning.machine import CPU_MIRRORED_STEPS_PER_S, CPU_STEPS_PER_S, choose_defaults, expected_duration
from learning.runner_config import PROFILES


def test_a_cpu_only_machine_gets_the_cpu_recipe_and_is_told_how_to_get_the_paper():
    d = choose_defaults(None, None, None, cuda_available=False, warp_available=True)
    assert (d.device, d.profile, d.sim) == ("cpu", "cpu_fast", None)
    line = d.describe("mujoco")
    assert "device cpu, profile cpu_fast, physics mujoco" in line and "no CUDA device" in line
    assert "--profile paper" in line


def test_the_oscillator_task_gets_the_recipe_under_which_policies_follow_their_oscillators():
    d = choose_defaults(None, None, None, cuda_available=False, warp_available=False, task="mini_cheetah_osc")
    assert d.profile == "cpu_envelope" and "cpu_envelope is the CPU recipe of mini_cheetah_osc" in d.describe("mujoco")
    assert choose_defaults(None, None, None, cuda_available=False, warp_available=False,
                           task="mini_cheetah").profile == "cpu_fast"
    d = choose_defaults(None, None, None, cuda_available=True, warp_available=True, task="mini_cheetah_osc")
    assert d.profile == "paper" and "(profile cpu_envelope)" in d.describe("warp")


@pytest.mark.parametrize("warp, sim", [(True, "warp"), (False, "mujoco")])
def test_a_cuda_machine_gets_the_papers_settings_and_warp_when_installed(warp, sim):
    d = choose_defaults(None, None, None, cuda_available=True, warp_available=warp)
    assert (d.device, d.profile, d.sim) == ("cuda", "paper", sim)
    line = d.describe(sim)
    assert "--device cpu" in line and "a CUDA device" in line
    assert ("gpu" in line) != warp  # the missing extra is named only when it is missing


def test_flags_given_always_win():
    d = choose_defaults("cpu", "paper", "warp", cuda_available=True, warp_available=True)
    assert (d.device, d.profile, d.sim) == ("cpu", "paper", "warp") and d.describe("warp").endswith("(as given)")
    d = choose_defaults("cpu", None, None, cuda_available=True, warp_available=True)
    assert (d.profile, d.sim) == ("cpu_fast", None)  # the profile follows the device asked for
    d = choose_defaults("cuda", "cpu_fast", None, cuda_available=True, warp_available=True)
    assert (d.profile, d.sim) == ("cpu_fast", "warp")


def test_a_resumed_run_keeps_its_profile_and_physics():
    d = choose_defaults(None, None, None, cuda_available=True, warp_available=True, resume=True)
    assert (d.device, d.profile, d.sim) == ("cuda", None, None)
    assert "keeps its own profile" in d.describe("mujoco")


def test_expected_duration_rests_on_the_measured_cpu_rate():
    fast = dict(o.split("=") for o in PROFILES["cpu_fast"].overrides)
    iterations, envs, steps = int(fast["train.max_iterations"]), int(fast["env.num_envs"]), int(
        fast["train.num_steps_per_env"])
    line = expected_duration("cpu", "mujoco", envs, steps, iterations)
    minutes = iterations * envs * steps / CPU_STEPS_PER_S / 60
    assert 3 < minutes < 20 and f"about {round(minutes)} min" in line and "22k env steps/s" in line
    # The mirrored update of cpu_oscillators costs more per env step.
    mirrored = expected_duration("cpu", "mujoco", envs, steps, iterations, mirrored=True)
    assert f"about {round(iterations * envs * steps / CPU_MIRRORED_STEPS_PER_S / 60)} min" in mirrored
    assert "and mirror augmentation" in mirrored and CPU_MIRRORED_STEPS_PER_S < CPU_STEPS_PER_S
    assert re.search(r"about [3-9]\.\d h", expected_duration("cpu", "mujoco", 4096, 32, 2000))  # the paper on a CPU
    # cpu_envelope's [256, 256, 128] networks take twice the time of the recipes' [128, 128, 64] (E51, E52); the
    # paper's networks without mirror augmentation were never timed on an idle CPU, so no figure is made up.
    envelope = expected_duration("cpu", "mujoco", 1024, 24, 1200, mirrored=True, hidden_dims=(256, 256, 128))
    assert "about 70 min for 1200 iterations" in envelope and "[256, 256, 128] networks" in envelope
    assert "no measured rate for cpu with mujoco physics and [256, 256, 128] networks" in expected_duration(
        "cpu", "mujoco", 1024, 32, 2000, hidden_dims=(256, 256, 128))
    # The paper on the one GPU measured (an H200 with Warp): about 23 minutes; other GPU setups have no rate.
    gpu = expected_duration("cuda", "warp", 4096, 32, 2000)
    assert re.search(r"about 2[0-9] min for 2000 iterations .* one NVIDIA H200", gpu)
    assert "no measured rate for cuda with mujoco" in expected_duration("cuda", "mujoco", 4096, 32, 2000)
    assert "no measured rate" in expected_duration("cuda", "warp", 4096, 32, 2000, world_size=2)
    # Two torchrun processes on the CPU share its cores: twice the env steps, twice the time.
    two = expected_duration("cpu", "mujoco", envs, steps, iterations, world_size=2)
    assert f"about {round(2 * minutes)} min for {iterations} iterations x {2 * envs * steps:,} env steps" in two


def test_a_run_says_what_it_chose_why_and_how_long_it_takes(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(launch, "_cuda_available", lambda: False)
    code = train.main(["--task", "mini_cheetah_osc", "--log_root", str(tmp_path), "--num_envs", "16",
                       "--num_threads", "1", "--max_iterations", "1", "--set", "train.num_steps_per_env=4"])
    assert code == 0
    first = capsys.readouterr().out.splitlines()[:2]
    assert first[0].startswith("settings: device cpu, profile cpu_envelope, physics mujoco (torch sees no CUDA device; "
                               "cpu_envelope is")
    assert first[1].startswith("expected duration: about 1 s for 1 iterations x 64 env steps")
    (experiment,) = os.listdir(tmp_path)
    (run,) = os.listdir(tmp_path / experiment)
    saved = (tmp_path / experiment / run / "train.yaml").read_text()
    assert "profile: cpu_envelope" in saved and "[256, 256, 128]" in saved  # the recipe's networks, the flags on top


def test_train_help_quotes_the_cpu_recipes_from_their_profiles(monkeypatch, capsys):
    import train
    from learning import runner_config

    iterations = runner_config.profile_setting("cpu_envelope", "train.max_iterations")
    assert f"cpu_envelope, {iterations} iterations, for mini_cheetah_osc" in train.build_parser().description
    changed = runner_config.Profile("x", runner_config.PROFILES["cpu_envelope"].overrides + ("train.max_iterations=7",))
    monkeypatch.setitem(runner_config.PROFILES, "cpu_envelope", changed)
    assert "cpu_envelope, 7 iterations" in train.build_parser().description
