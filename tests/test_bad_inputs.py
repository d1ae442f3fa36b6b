"""Every flag and every config key of train.py, play.py, sweep.py and the analysis CLIs, given bad values.

Each case must exit non-zero with at most two lines on stderr, no traceback, no new file, and without
building an env (validation comes first, which is also what keeps each case a few milliseconds).
The cases run in-process through each script's main(argv), the same code path as the command line.
"""

from __future__ import annotations

import os

import pytest

import play
import sweep
import train
from analysis import balanced_legs, disturbance, fixed_points, gait_emergence, obedience, pace_to_trot, report
from analysis.rollout import build_parser
from gym_envs.config import Check, OneOf, Ordered, Range, to_dict, yaml_text
from gym_envs.legged_robot import LeggedRobot
from gym_envs.mini_cheetah_osc import MiniCheetahOscCfg
from gym_envs.train_config import TrainCfg

ANALYSIS = {"analysis.report": report, "analysis.balanced_legs": balanced_legs,
            "analysis.disturbance": disturbance, "analysis.gait_emergence": gait_emergence,
            "analysis.pace_to_trot": pace_to_trot, "analysis.obedience": obedience}
# Provenance keys: any string is a valid value, and setting them changes nothing.
NO_BAD_VALUE = {"train.profile", "train.resumed_from"}
# Keys whose default (empty) gives the generic cases nothing to shape a bad value from.
BAD_GAIT_WEIGHTS = ["3", "[1.0, 2.0]", "[-1.0, 1.0, 1.0, 1.0]", "[0.0, 0.0, 0.0, 0.0]"]
BAD_VALUES_OF = {"osc.uncoupled_gait_weights": BAD_GAIT_WEIGHTS, "osc.second_stage.uncoupled_gait_weights": BAD_GAIT_WEIGHTS}


@pytest.fixture
def sandbox(tmp_path, monkeypatch):
    """cwd and log root in an empty folder holding one plain file; env builds are recorded, not run."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("ORCGYM_LOG_ROOT", str(tmp_path / "logs"))
    (tmp_path / "a_file").write_text("not a folder")
    built = []

    def no_env(self, cfg):
        built.append(cfg)
        raise AssertionError("an env was built")

    monkeypatch.setattr(LeggedRobot, "__init__", no_env)
    return tmp_path, built


def files(root):
    return sorted(os.path.join(d, f) for d, _, names in os.walk(root) for f in names)


def check_refused(main, argv, sandbox, capsys):
    root, built = sandbox
    before = files(root)
    code = main(argv)
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code != 0, f"{argv} was accepted"
    assert 1 <= len(lines) <= 2 and "Traceback" not in err, f"{argv}: {err}"
    assert not built, f"{argv} built an env before failing"
    assert files(root) == before, f"{argv} wrote files"


# --- flags ----------------------------------------------------------------------------------------

NOT_A_FLAG_VALUE = {"--help"}  # prints help and exits 0, by design


def bool_flag(flag):
    return [[f"{flag}=1"]]


COMMON_FLAGS = {
    "--debug": bool_flag("--debug"),
    "--device": [["--device", "tpu"]],
    "--sim": [["--sim", "nope"]],
    "--num_threads": [["--num_threads", "-2"], ["--num_threads", "two"]],
    "--set": [["--set", "no_equals_sign"], ["--set", "env.num_envs"]],
}
RUN_FLAGS = {
    "--load_run": [["--load_run", "missing_run"]],
    "--checkpoint": [["--checkpoint", "-2"], ["--checkpoint", "99"]],
    "--experiment_name": [["--experiment_name", "a/b"], ["--experiment_name", ".."]],
    "--log_root": [["--log_root", "a_file"]],
}
TRAIN_FLAGS = {
    **COMMON_FLAGS, **RUN_FLAGS,
    "--task": [["--task", "nope"]],
    "--orc": [["--orc", "12"], ["--orc", "1x1"]],
    "--num_envs": [["--num_envs", "0"], ["--num_envs", "-3"], ["--num_envs", "1.5"]],
    "--max_iterations": [["--max_iterations", "0"], ["--max_iterations", "-3"]],
    "--seed": [["--seed", "-2"], ["--seed", "x"]],
    "--headless": bool_flag("--headless"),
    "--resume": [["--resume"]],  # no run to resume under the empty log root
    "--run_name": [["--run_name", "a/b"]],
    "--profile": [["--profile", "nope"]],
    "--logger": [["--logger", "nope"]],
    "--log_project_name": [["--log_project_name", "team/project"], ["--log_project_name", ""]],
    "--video": [["--video", "0"], ["--video", "x"]],
    "--video_length": [["--video_length", "0"], ["--video_length", "nan"]],
    "--print_config": bool_flag("--print_config"),
}
PLAY_FLAGS = {
    **COMMON_FLAGS, **RUN_FLAGS,
    "--task": [["--task", "nope"]],
    "--orc": [["--orc", "1x1"]],
    "--shipped": [["--shipped=1"], ["--load_run", "x"]],  # the latter with the base's --shipped
    "--num_envs": [["--num_envs", "0"]],
    "--duration": [["--duration", "-1"], ["--duration", "0"], ["--duration", "nan"]],
    "--command": [["--command", "nan"], ["--command", "1", "2"], ["--command", "inf", "0", "0"]],
    "--osc_init": [["--osc_init", "gallop"]],
    "--coupling": [["--coupling", "maybe"]],
    "--noise": bool_flag("--noise"),
    "--pushes": bool_flag("--pushes"),
    "--randomize": bool_flag("--randomize"),
    "--seed": [["--seed", "-1"]],
    "--headless": bool_flag("--headless"),
    "--video": [["--video", "robot.avi"], ["--video", "no_such_folder/robot.mp4"]],
    "--export": bool_flag("--export"),
    "--print_config": bool_flag("--print_config"),
}
SWEEP_FLAGS = {
    **COMMON_FLAGS,
    "--out": [["--out", "a_file"]],
    "--orcs": [["--orcs", "111", "12"]],
    "--seeds": [["--seeds", "0", "-1"]],
    "--max_iterations": [["--max_iterations", "0"]],
    "--num_envs": [["--num_envs", "0"]],
    "--profile": [["--profile", "nope"]],
}
ANALYSIS_FLAGS = {
    "--debug": bool_flag("--debug"),
    "--runs": [["--runs", "no_such_folder"], ["--runs", "a_file"], ["--runs", "."]],  # "." holds no runs
    "--out": [["--out", "a_file"]],
    "--quick": bool_flag("--quick"),
    "--max_per_config": [["--max_per_config", "0"]],
    "--process_noise": [["--process_noise", "-1"], ["--process_noise", "nan"]],
    "--seed": [["--seed", "-1"]],
}
PUSH_FLAGS = {**ANALYSIS_FLAGS, "--push_slots": [["--push_slots", "0"], ["--push_slots", "100000"]],  # too many to fit
              "--push_command": [["--push_command", "0"], ["--push_command", "nan"]]}
PUSHING = {"analysis.report", "analysis.disturbance"}
FIXED_POINTS_FLAGS = {"--debug": bool_flag("--debug"), "--out": [["--out", "a_file"]], "--quick": bool_flag("--quick")}

SCRIPTS = {
    # name: (main, parser, base argv, bad values of every flag)
    "train.py": (train.main, train.build_parser(), ["--task", "mini_cheetah_osc", "--num_threads", "1"], TRAIN_FLAGS),
    "play.py": (play.main, play.build_parser(), ["--shipped", "--orc", "111", "--headless", "--num_envs", "2",
                                                 "--num_threads", "1"], PLAY_FLAGS),
    "sweep.py": (sweep.main, sweep.build_parser(), ["--orcs", "111", "--num_threads", "1", "--out", "sweep"],
                 SWEEP_FLAGS),
    **{name: (module.main, build_parser(name, "", pushes=name in PUSHING), ["--out", "out"],
              PUSH_FLAGS if name in PUSHING else ANALYSIS_FLAGS)
       for name, module in ANALYSIS.items()},
    "analysis.fixed_points": (fixed_points.main, fixed_points.build_parser(), [], FIXED_POINTS_FLAGS),
}


def parser_flags(name) -> set[str]:
    parser = SCRIPTS[name][1]
    return {s for a in parser._actions for s in a.option_strings if s.startswith("--")} - NOT_A_FLAG_VALUE


@pytest.mark.parametrize("name", list(SCRIPTS))
def test_every_flag_has_bad_values_here(name):
    assert parser_flags(name) == set(SCRIPTS[name][3]), "a flag was added or removed: give it bad values here"


@pytest.mark.parametrize("name", list(SCRIPTS))
def test_bad_flag_values_are_one_line_before_anything_is_built(name, sandbox, capsys):
    main, _, base, table = SCRIPTS[name]
    for cases in table.values():
        for case in cases:
            check_refused(main, base + case, sandbox, capsys)


# --- config keys ----------------------------------------------------------------------------------


def leaves(data, prefix=""):
    for key, value in data.items():
        if isinstance(value, dict) and value:
            yield from leaves(value, f"{prefix}{key}.")
        else:
            yield f"{prefix}{key}", value


def rule_of(key, rules):
    """The rule covering `key` (a rule on a dict covers each of its entries)."""
    for rule_key, rule in rules.items():
        if key == rule_key or key.startswith(rule_key + "."):
            return rule
    return None


def against_rule(rule, value) -> list:
    """Values of the same shape as `value` that break `rule`."""
    out = []
    for one in rule if isinstance(rule, tuple) else (rule,):
        if isinstance(one, Range):
            bad = (one.low if one.low_open else one.low - 1) if one.low is not None else (
                one.high if one.high_open else one.high + 1)
            bad = type(value[0] if isinstance(value, list) else value)(bad)
            out.append([bad] * len(value) if isinstance(value, list) else bad)
        elif isinstance(one, OneOf):
            out.append("nope")
        elif isinstance(one, Ordered):
            out.append([[1.0, -1.0]] * len(value) if isinstance(value[0], list) else [1.0, -1.0])
        elif isinstance(one, Check):
            out.append([] if isinstance(value, list) else "no/such")
    return out


def bad_values(key, value, rules) -> list[str]:
    """Override texts that must be refused: the wrong type, non-finite floats, and values outside the rule."""
    if key in BAD_VALUES_OF:
        return BAD_VALUES_OF[key]
    if isinstance(value, bool):
        texts = ["maybe"]
    elif isinstance(value, int):
        texts = ["x", "1.5"]
    elif isinstance(value, float):
        texts = ["x", ".nan", ".inf"]
    elif isinstance(value, list):
        texts = ["3"] + (["[.nan]"] if value and isinstance(value[0], float) else [])
    elif isinstance(value, dict):  # an empty one (others are walked into): not a mapping, or a name it cannot hold
        texts = ["3", "{no_such_name: 1.0}"]
    else:
        texts = []
    rule = rule_of(key, rules)
    if rule is not None:
        texts += [yaml_text(v).strip() if not isinstance(v, str) else v for v in against_rule(rule, value)]
    return [t.replace("\n", " ") for t in texts]


def config_cases(include_train: bool):
    cases = [(k, v) for k, v in leaves(to_dict(MiniCheetahOscCfg()))]
    if include_train:
        cases += [(f"train.{k}", v) for k, v in leaves(to_dict(TrainCfg()))]
    out = []
    for key, value in cases:
        if key in NO_BAD_VALUE or value is None:
            continue
        rules = TrainCfg.RULES if key.startswith("train.") else MiniCheetahOscCfg.RULES
        texts = bad_values(key.removeprefix("train."), value, rules) if key.startswith("train.") else \
            bad_values(key, value, rules)
        assert texts, f"no bad value known for config key {key}"
        out += [f"{key}={t}" for t in texts]
    return out


@pytest.mark.parametrize("name, include_train", [("train.py", True), ("play.py", False), ("sweep.py", True)])
def test_bad_config_values_are_one_line_before_anything_is_built(name, include_train, sandbox, capsys):
    main, _, base, _ = SCRIPTS[name]
    overrides = config_cases(include_train)
    assert len(overrides) > (250 if include_train else 150)
    for override in overrides:
        key = override.partition("=")[0]
        if key in ("env.device", "env.seed") + (sweep.SWEEP_KEYS if name == "sweep.py" else ()):
            continue  # refused whatever the value (below): the script sets them itself
        check_refused(main, base + ["--set", override], sandbox, capsys)


def test_a_train_key_in_play_and_env_keys_train_sets_itself_are_refused(sandbox, capsys):
    check_refused(play.main, SCRIPTS["play.py"][2] + ["--set", "train.seed=1"], sandbox, capsys)
    for override in ("env.device=cpu", "env.seed=3"):
        check_refused(train.main, SCRIPTS["train.py"][2] + ["--set", override], sandbox, capsys)
        check_refused(sweep.main, SCRIPTS["sweep.py"][2] + ["--set", override], sandbox, capsys)
    for key in sweep.SWEEP_KEYS:
        check_refused(sweep.main, SCRIPTS["sweep.py"][2] + ["--set", f"{key}=1"], sandbox, capsys)


@pytest.mark.parametrize("name", [n for n in SCRIPTS if n != "analysis.fixed_points"])  # it builds no env
def test_the_base_command_lines_get_as_far_as_building_an_env(name, sandbox, capsys):
    """So the cases above fail because of their bad value, not because the rest of the command line is wrong."""
    main, _, base, _ = SCRIPTS[name]
    main(base)
    assert sandbox[1], capsys.readouterr().err


def test_the_dashed_spelling_of_a_flag_still_works():
    args = build_parser("analysis.report", "", out_default="report").parse_args(
        ["--max-per-config", "3", "--process-noise=0.25"])
    assert (args.max_per_config, args.process_noise) == (3, 0.25)
