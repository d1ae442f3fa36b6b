"""Nothing lost, nothing silently wrong (issue 25): live runs, NaN and cut-short files, every analysis CLI.

Each test re-tries one fault of the issue's table: a resume or a second sweep while a run is written,
a checkpoint with a NaN weight, a run config cut at a line boundary, the analysis command lines, empty
environment variables, incomplete run folders, Ctrl-C during the imports, a missing OpenGL backend,
and the small ones (play's Ctrl-C status, max_iterations: -5, an --out that cannot be written).
"""

from __future__ import annotations

import dataclasses
import glob
import os
import pkgutil
import re
import runpy
import shutil
import signal
import subprocess
import sys
import warnings

import pytest
import torch

import analysis
import play
import sweep
import train
from gym_envs.config import ConfigError
from learning import runs
from learning.vec_env import TaskVecEnv

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TINY = ["--num_envs", "16", "--num_threads", "1", "--set", "train.num_steps_per_env=4"]


def one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert err and "\n" not in err and "Traceback" not in err, err
    return err


def files_under(root) -> list[str]:
    return sorted(os.path.relpath(os.path.join(d, f), root) for d, _, names in os.walk(root) for f in names)


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """A 1-iteration run of 16 robots (model_0, model_1); tests copy it before changing anything."""
    root = tmp_path_factory.mktemp("logs")
    assert train.main(["--task", "mini_cheetah_osc", "--log_root", str(root), "--max_iterations", "1", *TINY]) == 0
    (name,) = os.listdir(root / "ORC_111")
    return str(root / "ORC_111" / name)


@pytest.fixture
def run_copy(tiny_run, tmp_path):
    path = tmp_path / "runs" / "ORC_111" / os.path.basename(tiny_run)
    shutil.copytree(tiny_run, path)
    return str(path)


def resume(run_dir, log_root, *args) -> int:
    return train.main(["--resume", "--load_run", run_dir, "--log_root", str(log_root), "--max_iterations", "1",
                       "--num_threads", "1", *args])


# --- 1, 2: a run folder is owned by the process writing it ----------------------------------------------


def test_a_run_records_its_format_and_train_py_holds_its_lock_while_training(tmp_path, capsys, monkeypatch):
    step, refusals = TaskVecEnv.step, []

    def step_and_try_to_resume_the_live_run(self, actions):
        if not refusals:
            (live,) = os.listdir(tmp_path / "ORC_111")
            refusals.append(resume(str(tmp_path / "ORC_111" / live), tmp_path / "other"))
        return step(self, actions)

    monkeypatch.setattr(TaskVecEnv, "step", step_and_try_to_resume_the_live_run)
    assert train.main(["--task", "mini_cheetah_osc", "--log_root", str(tmp_path), "--max_iterations", "1",
                       *TINY]) == 0
    assert refusals == [1]
    err = capsys.readouterr().err
    assert f"is being written by process {os.getpid()}" in err and "--load_run" in err
    assert not (tmp_path / "other").exists()
    (name,) = os.listdir(tmp_path / "ORC_111")
    assert runs.run_format(str(tmp_path / "ORC_111" / name)) == runs.RUN_FORMAT


HOLDER = """
import sys, time
from learning.runs import FolderLock
lock = FolderLock(sys.argv[1], "unused")
open(sys.argv[2], "wb").write(b"half a checkpoint")  # the live run's save in progress
print("holding", flush=True)
time.sleep(600)
"""


def test_resume_of_a_live_run_is_refused_and_its_save_in_progress_survives(run_copy, tmp_path, capsys):
    in_progress = os.path.join(run_copy, ".model_2.pt.abc123.tmp")
    holder = subprocess.Popen([sys.executable, "-c", HOLDER, run_copy, in_progress], cwd=REPO,
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "holding"
        assert resume(run_copy, tmp_path / "resumed") == 1
        err = one_line(capsys)
        assert f"{run_copy} is being written by process {holder.pid} (-c)" in err
        assert os.path.isfile(in_progress) and not (tmp_path / "resumed").exists()
    finally:
        holder.kill()  # as a crash would: the kernel drops the lock, nothing stale is left
        holder.wait(timeout=30)
    assert resume(run_copy, tmp_path / "resumed") == 0
    assert not os.path.exists(in_progress)  # now a stale file of a dead save: removed
    (new,) = os.listdir(tmp_path / "resumed" / "ORC_111")
    assert runs.list_checkpoints(str(tmp_path / "resumed" / "ORC_111" / new)) == [2]


def test_a_second_sweep_into_the_same_out_is_refused_while_the_first_runs(tmp_path, capsys, monkeypatch):
    argv = ["--out", str(tmp_path), "--orcs", "111", "--seeds", "0", "--max_iterations", "1", *TINY]
    step, second = TaskVecEnv.step, []

    def step_and_start_a_second_sweep(self, actions):
        if not second:
            second.append(sweep.main(argv))
        return step(self, actions)

    monkeypatch.setattr(TaskVecEnv, "step", step_and_start_a_second_sweep)
    assert sweep.main(argv) == 0
    assert second == [1]
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{tmp_path} is being written by process {os.getpid()}" in err[0], err
    assert "choose another --out" in err[0]
    run_dir = tmp_path / "ORC_111" / "seed0"
    assert len([f for f in os.listdir(run_dir) if f.startswith("events.out")]) == 1
    assert runs.list_checkpoints(str(run_dir)) == [0, 1]


# --- 3: a checkpoint with a NaN weight ----------------------------------------------------------------


def poison(run_dir) -> str:
    path = runs.checkpoint_path(run_dir, 1)
    data = torch.load(path, weights_only=True)
    data["actor_state_dict"]["mlp.0.weight"][3, 5] = float("nan")
    torch.save(data, path)
    return path


def test_a_nan_checkpoint_is_refused_by_play_export_analysis_and_resume(run_copy, tmp_path, capsys):
    from analysis import balanced_legs

    path = poison(run_copy)
    refusal = f"refused checkpoint {path}: tensor actor_state_dict.mlp.0.weight holds 1 NaN or infinite values"
    before = files_under(tmp_path)
    play_argv = ["--load_run", run_copy, "--headless", "--num_envs", "2", "--duration", "0.05", "--num_threads", "1"]
    for argv in (play_argv, play_argv + ["--export"]):
        assert play.main(argv) == 1
        err = one_line(capsys)
        assert refusal in err and "--checkpoint N (its run also has 0)" in err
    assert balanced_legs.main(["--runs", run_copy, "--out", str(tmp_path / "out"), "--quick"]) == 1
    assert refusal in one_line(capsys)
    assert resume(run_copy, tmp_path / "resumed") == 1
    assert refusal in one_line(capsys)
    assert files_under(tmp_path) == before  # no export, no CSV, no run folder


def test_export_refuses_a_policy_that_went_non_finite(run_copy, tmp_path):
    from learning.export import export_deployment

    session = play.Session(play.build_parser().parse_args(["--load_run", run_copy, "--num_envs", "1"]))
    with torch.no_grad():
        next(session.policy.model.parameters()).fill_(float("inf"))
    with pytest.raises(ConfigError, match=r"not exporting model_1.pt: tensor .* holds \d+ NaN or infinite"):
        export_deployment(session.policy.model, session.task, str(tmp_path / "exported"), "model_1.pt")
    assert not (tmp_path / "exported").exists()


# --- 4: a saved run config cut short --------------------------------------------------------------------


@pytest.mark.parametrize("name", [runs.ENV_YAML, runs.TRAIN_YAML])
def test_a_run_config_cut_at_any_line_is_an_error_naming_what_is_missing(run_copy, name):
    path = os.path.join(run_copy, name)
    text = open(path).read()
    cuts = [i + 1 for i, c in enumerate(text[:-1]) if c == "\n"]
    assert len(cuts) > 20
    for cut in cuts:
        with open(path, "w") as f:
            f.write(text[:cut])
        # (a list of lists cut between its items is a list too short)
        with pytest.raises(ConfigError, match=rf"^{path}: (config key '[\w.]+' is missing|invalid YAML|invalid "
                                              rf"value for config key '[\w.]+': expected .* with 3 items, got [12])"):
            runs.load_run_configs(run_copy)


def test_a_cut_env_yaml_is_refused_by_play_and_resume_and_older_runs_still_load(run_copy, tmp_path, capsys):
    path = os.path.join(run_copy, runs.ENV_YAML)
    text = open(path).read()
    with open(path, "w") as f:  # the case: 1500 bytes, cut at a line boundary
        f.write(text[:text.rindex("\n", 0, 1500) + 1])
    before = files_under(tmp_path)
    assert play.main(["--load_run", run_copy, "--headless", "--num_envs", "2", "--num_threads", "1"]) == 1
    assert re.search(rf"{path}: config key '[\w.]+' is missing; .* restore it", one_line(capsys))
    assert resume(run_copy, tmp_path / "resumed") == 1
    assert "is missing" in one_line(capsys)
    assert files_under(tmp_path) == before

    # A folder written before run formats existed (no format.yaml) takes the defaults for what it lacks...
    os.remove(os.path.join(run_copy, runs.FORMAT_YAML))
    assert runs.run_format(run_copy) == 0
    runs.load_run_configs(run_copy)
    # ...and one from a newer orcgym is refused rather than misread.
    with open(os.path.join(run_copy, runs.FORMAT_YAML), "w") as f:
        f.write(f"run_format: {runs.RUN_FORMAT + 1}\n")
    with pytest.raises(runs.RunError, match=r"written by a newer orcgym .*; update orcgym"):
        runs.load_run_configs(run_copy)


def test_a_run_from_before_a_reward_term_resumes_into_a_folder_that_loads(run_copy, tmp_path):
    # Format 6 predates rewards.weights.swing_contact: its weights lack the entry, which then takes the
    # default (0), and the resumed run saves it, so that the new folder loads as a complete one.
    path = os.path.join(run_copy, runs.ENV_YAML)
    text = open(path).read()
    with open(path, "w") as f:
        f.write(re.sub(r"^    swing_contact: .*\n", "", text, flags=re.M))
    with open(os.path.join(run_copy, runs.FORMAT_YAML), "w") as f:
        f.write("run_format: 6\n")
    assert runs.load_run_configs(run_copy)[1].rewards.weights["swing_contact"] == 0.0
    assert resume(run_copy, tmp_path / "resumed") == 0
    (resumed,) = glob.glob(str(tmp_path / "resumed" / "*" / "*"))
    assert runs.run_format(resumed) == runs.RUN_FORMAT
    assert runs.load_run_configs(resumed)[1].rewards.weights["swing_contact"] == 0.0


FORWARD_ONLY_POLICY = os.path.join(runs.REPO_ROOT, "resources", "policies_forward_only", "ORC_111", "seed0")


def test_older_runs_keep_the_yaw_term_they_trained_with():
    # The archived forward-only set predates rewards.yaw_tracking and trained with the released quartic; a run
    # that names its term keeps it.
    _, archived, _ = runs.load_run_configs(FORWARD_ONLY_POLICY)
    assert runs.run_format(FORWARD_ONLY_POLICY) == 0
    assert archived.rewards.yaw_tracking == "released_quartic" and archived.osc.standing_rule == "lin_vel_x"
    _, shipped, _ = runs.load_run_configs(runs.shipped_policy_dir("111"))
    assert shipped.rewards.yaw_tracking == "sqexp" and shipped.osc.standing_rule == "command"


def test_a_format_0_run_that_names_its_yaw_term_keeps_it(run_copy):
    path = os.path.join(run_copy, runs.ENV_YAML)
    text = open(path).read()
    assert re.search(r"^  yaw_tracking: \w+$", text, re.M)
    with open(path, "w") as f:
        f.write(re.sub(r"^  yaw_tracking: \w+$", "  yaw_tracking: sqexp", text, flags=re.M))
    os.remove(os.path.join(run_copy, runs.FORMAT_YAML))
    assert runs.load_run_configs(run_copy)[1].rewards.yaw_tracking == "sqexp"


# --- 5: every analysis command line ----------------------------------------------------------------------


def analysis_clis() -> list[str]:
    names = [m.name for m in pkgutil.iter_modules(analysis.__path__)]
    return [n for n in names if hasattr(__import__(f"analysis.{n}", fromlist=["main"]), "main")]


def test_every_analysis_module_with_a_main_is_covered():
    assert set(analysis_clis()) == {"balanced_legs", "disturbance", "envelope", "fixed_points", "gait_emergence",
                                    "obedience", "pace_to_trot", "report"}


def run_as_main(module: str, argv: list[str]) -> int:
    """`python -m analysis.<module> ARGV` in this process: runpy, as -m does, so the __main__ block counts."""
    old = sys.argv
    sys.argv = [module, *argv]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # "found in sys.modules": it is, imported above
            runpy.run_module(f"analysis.{module}", run_name="__main__")
    except SystemExit as done:
        return done.code
    finally:
        sys.argv = old
    raise AssertionError(f"python -m analysis.{module} did not exit with a status")


@pytest.mark.parametrize("module", analysis_clis())
def test_python_m_analysis_help_works_and_errors_exit_non_zero(module, tmp_path, capsys):
    assert run_as_main(module, ["--help"]) == 0
    assert capsys.readouterr().out.startswith(f"usage: analysis.{module}")
    (tmp_path / "a_file").write_text("")
    assert run_as_main(module, ["--out", str(tmp_path / "a_file")]) == 2  # a malformed flag value
    assert "a_file" in one_line(capsys)
    if module != "fixed_points":
        assert run_as_main(module, ["--runs", str(tmp_path / "none"), "--out", str(tmp_path / "out")]) == 1
        assert "does not exist" in one_line(capsys)


@pytest.fixture
def smallest_sizes(monkeypatch):
    """Every analysis's --quick sizes cut to the least its metrics need: seconds, not minutes."""
    from analysis import balanced_legs, disturbance, envelope, gait_emergence, obedience, pace_to_trot

    monkeypatch.setattr(balanced_legs, "QUICK", {"robots_per_policy": 2, "duration_s": 1.0})
    monkeypatch.setattr(gait_emergence, "QUICK", {"runs": 2, "duration_s": 5.0})
    monkeypatch.setattr(pace_to_trot, "QUICK", {"runs": 2, "duration_s": 5.0})
    # every key of the real QUICK cut down, so a size added to the protocol cannot be missed here
    monkeypatch.setattr(obedience, "QUICK", {key: 5.0 if key.endswith("duration_s") else 2 for key in obedience.QUICK})
    monkeypatch.setattr(envelope, "QUICK", {"robots": 1, "warmup_s": 0.1, "measure_s": 5.0})
    monkeypatch.setattr(envelope, "ENVELOPE", {name: envelope.ENVELOPE[name] for name in ("stand", "forward 1")})
    monkeypatch.setattr(disturbance, "QUICK_MAGNITUDES", (2.0,))
    monkeypatch.setattr(disturbance, "QUICK_BALL", dataclasses.replace(
        disturbance.QUICK_BALL, slots=1, directions=2, settle_s=0.2, test_s=0.6, push_at_s=0.1))


@pytest.mark.parametrize("module", analysis_clis())
def test_a_tiny_quick_run_of_every_analysis(module, tiny_run, tmp_path, capsys, smallest_sizes):
    """Over a runs folder with one run and one incomplete folder, which each analysis names as skipped."""
    root = tmp_path / "runs"
    shutil.copytree(tiny_run, root / "ORC_111" / "complete")
    shutil.copytree(tiny_run, root / "ORC_111" / "no_env_yaml")
    os.remove(root / "ORC_111" / "no_env_yaml" / runs.ENV_YAML)
    out = tmp_path / "out"
    argv = ["--out", str(out), "--quick"] + ([] if module == "fixed_points" else ["--runs", str(root)])
    assert __import__(f"analysis.{module}", fromlist=["main"]).main(argv) == 0
    captured = capsys.readouterr()
    assert os.listdir(out) and str(out) in captured.out
    if module != "fixed_points":
        assert f"skipped {root / 'ORC_111' / 'no_env_yaml'}: no env.yaml" in captured.err
    if module == "report":
        text = (out / "report.md").read_text()
        assert "no_env_yaml: no env.yaml" in text
        assert "Falls before the first push" in text and "over 0.5 s)" in text  # reported even when none fell


# --- 6, 7: empty environment variables, incomplete run folders ---------------------------------------------


def test_an_empty_environment_variable_counts_as_unset(monkeypatch):
    from learning.video import prefer_offscreen_gl

    monkeypatch.setenv("ORCGYM_LOG_ROOT", "")
    assert runs.default_log_root() == runs.DEFAULT_LOG_ROOT
    assert sweep.build_parser().parse_args([]).out == os.path.join(runs.DEFAULT_LOG_ROOT, "sweep")
    for name in ("MUJOCO_GL", "DISPLAY", "WAYLAND_DISPLAY"):
        monkeypatch.setenv(name, "")
    prefer_offscreen_gl()
    assert os.environ["MUJOCO_GL"] == "egl"


def test_incomplete_run_folders_are_named_with_what_they_lack(tiny_run, tmp_path):
    for name, remove in (("complete", None), ("no_env", runs.ENV_YAML), ("no_train", runs.TRAIN_YAML),
                         ("starting", "model_*")):
        shutil.copytree(tiny_run, tmp_path / "ORC_111" / name)
        for path in (tmp_path / "ORC_111" / name).glob(remove or "-"):
            path.unlink()
    found, skipped = runs.scan_runs(str(tmp_path))
    assert found == [str(tmp_path / "ORC_111" / "complete")]
    assert skipped == [(str(tmp_path / "ORC_111" / "no_env"), "no env.yaml"),
                       (str(tmp_path / "ORC_111" / "no_train"), "no train.yaml"),
                       (str(tmp_path / "ORC_111" / "starting"), "no a checkpoint model_<it>.pt")]
    with pytest.raises(runs.RunError, match=r"no_train has no train.yaml; a run folder needs"):
        runs.load_run_configs(str(tmp_path / "ORC_111" / "no_train"))


# --- 8, 9: Ctrl-C during the imports, a missing OpenGL backend ------------------------------------------------

CTRL_C_AT_TORCH = """
import builtins, os, runpy, signal, sys
sys.path.insert(0, os.getcwd())
target, sys.argv = sys.argv[1], sys.argv[1:]
# A process whose parent ignored SIGINT inherits that, and then no Ctrl-C reaches it; a terminal's does.
signal.signal(signal.SIGINT, signal.default_int_handler)
real_import = builtins.__import__

def ctrl_c_at_torch(name, *args, **kwargs):
    if name == "torch":  # the first slow import of every command
        builtins.__import__ = real_import
        os.kill(os.getpid(), signal.SIGINT)
    return real_import(name, *args, **kwargs)

builtins.__import__ = ctrl_c_at_torch
if target.endswith(".py"):
    runpy.run_path(target, run_name="__main__")
else:
    runpy.run_module(target, run_name="__main__", alter_sys=True)
"""


@pytest.mark.parametrize("target", ["train.py", "play.py", "sweep.py", "analysis.obedience"])
def test_ctrl_c_during_the_imports_is_one_line(target):
    proc = subprocess.run([sys.executable, "-c", CTRL_C_AT_TORCH, target, "--help"], cwd=REPO, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == -signal.SIGINT, proc.stderr  # killed by SIGINT, as Python ends on Ctrl-C: 130 in a shell
    assert proc.stderr.strip().endswith("interrupted while starting up; nothing was written (run the command again)")
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr


def test_a_gl_backend_that_is_not_installed_is_one_line_naming_the_fix(tmp_path):
    env = {**os.environ, "MUJOCO_GL": "osmesa"}
    probe = subprocess.run([sys.executable, "-c", "import mujoco"], env=env, capture_output=True, timeout=120)
    if probe.returncode == 0:
        pytest.skip("OSMesa is installed here")
    proc = subprocess.run([sys.executable, "play.py", "--shipped", "--headless", "--num_envs", "1", "--num_threads",
                           "1", "--duration", "0.05", "--video", str(tmp_path / "robot.mp4")],
                          cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1
    err = proc.stderr.strip()
    assert "\n" not in err and "MuJoCo cannot load the OpenGL backend MUJOCO_GL=osmesa" in err, err
    assert "install libosmesa6" in err and not os.listdir(tmp_path)


# --- 10: the small ones -------------------------------------------------------------------------------------


def test_ctrl_c_in_play_prints_the_summary_and_exits_130(tiny_run, capsys, monkeypatch):
    step, calls = TaskVecEnv.step, []

    def step_then_ctrl_c(self, actions):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return step(self, actions)

    monkeypatch.setattr(TaskVecEnv, "step", step_then_ctrl_c)
    assert play.main(["--load_run", tiny_run, "--headless", "--num_envs", "2", "--num_threads", "1"]) == 130
    out = capsys.readouterr().out
    assert "interrupted" in out and "mean forward velocity" in out and "over 0.02 s" in out


def test_a_train_yaml_with_negative_max_iterations_is_flagged(run_copy, tmp_path, capsys):
    path = os.path.join(run_copy, runs.TRAIN_YAML)
    text = open(path).read()
    assert "\nmax_iterations: 1\n" in text
    with open(path, "w") as f:
        f.write(text.replace("\nmax_iterations: 1\n", "\nmax_iterations: -5\n"))
    expected = f"{path}: config key 'train.max_iterations' is -5; allowed: a number >= 1"
    assert resume(run_copy, tmp_path / "resumed") == 1
    assert expected in one_line(capsys)
    assert play.main(["--load_run", run_copy, "--headless", "--num_envs", "2"]) == 1
    assert expected in one_line(capsys)
    assert not (tmp_path / "resumed").exists()


def test_an_analysis_finds_an_unwritable_out_before_its_rollouts(tiny_run, tmp_path, capsys, monkeypatch):
    from analysis import balanced_legs

    def no_rollouts(*args, **kwargs):
        raise AssertionError("rollouts started")

    monkeypatch.setattr(balanced_legs, "run_jobs", no_rollouts)
    (tmp_path / "a_file").write_text("")
    out = tmp_path / "a_file" / "results"  # a folder under a file: no one can write it
    assert balanced_legs.main(["--runs", tiny_run, "--out", str(out), "--quick"]) == 1
    assert f"--out {out} cannot be written (Not a directory); choose a folder" in one_line(capsys)


def config_keys_digest() -> str:
    """A digest of every key of every task's default env and train configs."""
    import hashlib

    from gym_envs.config import to_dict
    from gym_envs.registry import TASKS, env_cfg_class, train_cfg_class

    def keys(data, prefix=""):
        for key, value in data.items():
            # dict-valued entries such as rewards.weights hold names, not config keys
            if isinstance(value, dict) and key not in ("weights", "scales", "noise"):
                yield from keys(value, f"{prefix}{key}.")
            else:
                yield prefix + key

    names = sorted({k for task in TASKS for part, cfg in (("env", env_cfg_class(task)()), ("train", train_cfg_class(task)()))
                    for k in keys(to_dict(cfg), f"{task}.{part}:")})
    return hashlib.sha256("\n".join(names).encode()).hexdigest()[:16]


# The config keys' digest that each run format was written with (format 2's keys labelled by task since the
# registry pairs each task with its configs: the keys are those of the class-named digest 9eacc93b081d44ec).
KEYS_OF_FORMAT = {2: "6b1159e500700287", 3: "5f2bc8c84249e8a0", 4: "779b2d189df46412", 5: "39e700cc1b18be7b",
                  6: "a94f8f2392378377", 7: "a94f8f2392378377", 8: "1ea1c33f8f452d03",
                  9: "77a868b996f55a60"}


def test_config_keys_change_only_with_the_run_format():
    assert config_keys_digest() == KEYS_OF_FORMAT.get(runs.RUN_FORMAT), (
        f"the config keys changed (digest {config_keys_digest()}): bump learning.runs.RUN_FORMAT so that saved "
        f"runs of the old format stay loadable, and record the digest in KEYS_OF_FORMAT")
