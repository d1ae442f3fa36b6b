"""Tests for gym_envs.config (typed dataclass configs <-> dict / YAML / CLI overrides)."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Literal, Optional

import pytest
import yaml

from gym_envs.config import ConfigError, apply_overrides, from_dict, load_yaml, save_yaml, to_dict


# ---------------------------------------------------------------- example configs (string annotations on purpose)


@dataclass
class EnvCfg:
    num_envs: int = 4096
    episode_length_s: float = 20.0
    seed: Optional[int] = None
    use_gpu: bool = True
    backend: Literal["cpu", "warp"] = "cpu"


@dataclass
class CommandsCfg:
    lin_vel_x: tuple[float, float] = (-1.0, 1.0)
    heading: tuple[float, ...] = (0.0,)


@dataclass
class RewardsCfg:
    weights: dict[str, float] = field(default_factory=lambda: {"tracking_lin_vel": 1.0, "torques": -1e-5})
    only_positive: bool = False


@dataclass
class TerrainCfg:
    size: float = 8.0
    kind: str = "flat"


@dataclass
class BaseCfg:
    name: str = "base"
    env: EnvCfg = field(default_factory=EnvCfg)
    commands: CommandsCfg = field(default_factory=CommandsCfg)
    rewards: RewardsCfg = field(default_factory=RewardsCfg)
    tags: list[str] = field(default_factory=list)
    learning_rate: float = 1e-3
    init_noise_std: float | None = None
    extras: dict[str, float] = field(default_factory=dict)
    terrain: Optional[TerrainCfg] = None


@dataclass
class GaitRewardsCfg(RewardsCfg):
    weights: dict[str, float] = field(
        default_factory=lambda: {"tracking_lin_vel": 1.5, "torques": -2e-5, "feet_air_time": 0.5}
    )


@dataclass
class GaitCfg(BaseCfg):
    name: str = "gait"
    env: EnvCfg = field(default_factory=lambda: EnvCfg(num_envs=1024, episode_length_s=15.0))
    rewards: GaitRewardsCfg = field(default_factory=GaitRewardsCfg)
    tags: list[str] = field(default_factory=lambda: ["quadruped", "cpg"])


def _tricky() -> GaitCfg:
    """A config full of values that are easy to corrupt on a YAML round trip."""
    cfg = GaitCfg()
    cfg.learning_rate = 0.1 + 0.2  # 0.30000000000000004
    cfg.init_noise_std = 1 / 3
    cfg.env.seed = 0
    cfg.commands.lin_vel_x = (-2.5e-7, 1e20)
    cfg.commands.heading = (float("inf"), -0.0, 1e-5)
    cfg.rewards.weights["torques"] = -1.2345678901234567e-05
    cfg.tags = ["1e-3", "yes", "off", "017", "null", "2024-01-01", "1:30", "true", ""]
    cfg.name = "1e5"
    return cfg


# ---------------------------------------------------------------- to_dict / from_dict


def test_to_dict_is_plain_and_ordered():
    d = to_dict(GaitCfg())
    assert list(d) == ["name", "env", "commands", "rewards", "tags", "learning_rate", "init_noise_std", "extras",
                       "terrain"]
    assert list(d["env"]) == ["num_envs", "episode_length_s", "seed", "use_gpu", "backend"]
    assert d["commands"]["lin_vel_x"] == [-1.0, 1.0] and isinstance(d["commands"]["lin_vel_x"], list)
    assert d["env"]["num_envs"] == 1024
    assert d["rewards"]["weights"] == {"tracking_lin_vel": 1.5, "torques": -2e-5, "feet_air_time": 0.5}
    yaml.safe_dump(d)  # only plain types


def test_dict_round_trip():
    cfg = _tricky()
    assert from_dict(GaitCfg, to_dict(cfg)) == cfg


def test_from_dict_missing_keys_take_derived_defaults():
    cfg = from_dict(GaitCfg, {"env": {"seed": 3}})
    assert cfg.env == EnvCfg(num_envs=1024, episode_length_s=15.0, seed=3)
    assert cfg.rewards.weights["feet_air_time"] == 0.5
    assert cfg.name == "gait"


@dataclass
class SubclassDefaultCfg(BaseCfg):
    rewards: RewardsCfg = field(default_factory=GaitRewardsCfg)  # annotation is the base class


def test_from_dict_partial_section_keeps_subclass_default():
    cfg = from_dict(SubclassDefaultCfg, {"rewards": {"only_positive": True}})
    assert type(cfg.rewards) is GaitRewardsCfg and cfg.rewards.only_positive is True
    assert cfg.rewards.weights == GaitRewardsCfg().weights


def test_optional_section():
    assert from_dict(BaseCfg, {}).terrain is None
    assert from_dict(BaseCfg, {"terrain": {"size": 2}}).terrain == TerrainCfg(size=2.0)
    cfg = apply_overrides(BaseCfg(), ["terrain={kind: rough}"])
    assert cfg.terrain == TerrainCfg(kind="rough")
    assert apply_overrides(cfg, ["terrain.size=1", "terrain.kind=stairs"]).terrain == TerrainCfg(1.0, "stairs")
    assert apply_overrides(cfg, ["terrain=null"]).terrain is None
    with pytest.raises(ConfigError, match="did you mean 'terrain.size'"):
        from_dict(BaseCfg, {"terrain": {"sise": 2}})


def test_from_dict_coerces():
    cfg = from_dict(BaseCfg, {"learning_rate": 1, "commands": {"lin_vel_x": [-1, 2], "heading": [1, 2, 3]}})
    assert cfg.learning_rate == 1.0 and isinstance(cfg.learning_rate, float)
    assert cfg.commands.lin_vel_x == (-1.0, 2.0) and isinstance(cfg.commands.lin_vel_x, tuple)
    assert all(isinstance(x, float) for x in cfg.commands.heading)


def test_from_dict_unknown_key_suggests():
    with pytest.raises(ConfigError) as exc:
        from_dict(BaseCfg, {"env": {"num_env": 8}})
    msg = str(exc.value)
    assert "'env.num_env'" in msg and "did you mean 'env.num_envs'?" in msg and "valid keys in 'env'" in msg
    with pytest.raises(ConfigError, match="did you mean 'rewards'"):
        from_dict(BaseCfg, {"reward": {}})


@pytest.mark.parametrize(
    "data, key, expected",
    [
        ({"env": {"num_envs": "many"}}, "env.num_envs", "int"),
        ({"env": {"num_envs": 1.5}}, "env.num_envs", "int"),
        ({"env": {"use_gpu": 1}}, "env.use_gpu", "bool"),
        ({"env": {"use_gpu": "yes"}}, "env.use_gpu", "bool"),
        ({"env": {"seed": "x"}}, "env.seed", "int | None"),
        ({"env": {"backend": "cuda"}}, "env.backend", "one of 'cpu', 'warp'"),
        ({"learning_rate": True}, "learning_rate", "float"),
        ({"learning_rate": "1e-3"}, "learning_rate", "float"),
        ({"commands": {"lin_vel_x": [1.0, 2.0, 3.0]}}, "commands.lin_vel_x", "tuple[float, float]"),
        ({"commands": {"heading": [0.0, "a"]}}, "commands.heading[1]", "float"),
        ({"tags": ["a", 3]}, "tags[1]", "str"),
        ({"rewards": {"weights": {"torques": "big"}}}, "rewards.weights.torques", "float"),
        ({"env": 5}, "env", "EnvCfg"),
    ],
)
def test_from_dict_wrong_type(data, key, expected):
    with pytest.raises(ConfigError) as exc:
        from_dict(BaseCfg, data)
    msg = str(exc.value)
    assert f"'{key}'" in msg and expected in msg and "\n" not in msg


def test_from_dict_optional_accepts_none():
    assert from_dict(BaseCfg, {"env": {"seed": None}, "init_noise_std": None}).env.seed is None


# ---------------------------------------------------------------- YAML


def test_yaml_round_trip_exact(tmp_path):
    cfg = _tricky()
    path = tmp_path / "config.yaml"
    save_yaml(cfg, path)
    loaded = load_yaml(GaitCfg, path)
    assert loaded == cfg
    assert repr(loaded.learning_rate) == repr(cfg.learning_rate)
    assert loaded.tags == cfg.tags and loaded.name == "1e5"
    # The file is also read identically by a standard YAML loader.
    assert yaml.safe_load(path.read_text()) == to_dict(cfg)


def test_yaml_hand_written_file(tmp_path):
    path = tmp_path / "cfg.yaml"
    path.write_text("learning_rate: 1e-3\nenv:\n  num_envs: 8\n  use_gpu: false\ncommands:\n  lin_vel_x: [-1, 2]\n")
    cfg = load_yaml(GaitCfg, path)
    assert cfg.learning_rate == 1e-3 and cfg.env.num_envs == 8 and cfg.env.use_gpu is False
    assert cfg.env.episode_length_s == 15.0  # missing -> derived default
    assert cfg.commands.lin_vel_x == (-1.0, 2.0)


def test_yaml_unknown_key_names_file(tmp_path):
    path = tmp_path / "cfg.yaml"
    path.write_text("env:\n  num_env: 8\n")
    with pytest.raises(ConfigError) as exc:
        load_yaml(GaitCfg, path)
    msg = str(exc.value)
    assert str(path) in msg and "did you mean 'env.num_envs'?" in msg and "\n" not in msg


def test_yaml_yes_is_not_a_bool(tmp_path):
    path = tmp_path / "cfg.yaml"
    path.write_text("env:\n  use_gpu: yes\n")
    with pytest.raises(ConfigError, match="env.use_gpu.*bool"):
        load_yaml(GaitCfg, path)


def test_yaml_syntax_error_is_one_line(tmp_path):
    path = tmp_path / "cfg.yaml"
    path.write_text("env: [1, 2\n")
    with pytest.raises(ConfigError) as exc:
        load_yaml(GaitCfg, path)
    assert str(path) in str(exc.value) and "\n" not in str(exc.value)


def test_save_is_atomic_and_leaves_no_temp_files(tmp_path, monkeypatch):
    path = tmp_path / "config.yaml"
    save_yaml(GaitCfg(), path)
    save_yaml(_tricky(), path)  # overwrite
    assert os.listdir(tmp_path) == ["config.yaml"]
    before = path.read_text()

    def failing_replace(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", failing_replace)
    with pytest.raises(OSError, match="disk full"):
        save_yaml(GaitCfg(), path)
    assert os.listdir(tmp_path) == ["config.yaml"]
    assert path.read_text() == before


def test_save_refuses_invalid_config(tmp_path):
    cfg = GaitCfg()
    cfg.env.num_envs = "lots"
    with pytest.raises(ConfigError, match="env.num_envs"):
        save_yaml(cfg, tmp_path / "config.yaml")
    assert os.listdir(tmp_path) == []


# ---------------------------------------------------------------- overrides


@pytest.mark.parametrize(
    "override, get, expected",
    [
        ("env.num_envs=8", lambda c: c.env.num_envs, 8),
        ("env.num_envs=-2", lambda c: c.env.num_envs, -2),
        ("learning_rate=1e-3", lambda c: c.learning_rate, 1e-3),
        ("learning_rate=-2", lambda c: c.learning_rate, -2.0),
        ("learning_rate=1.5E3", lambda c: c.learning_rate, 1500.0),
        ("learning_rate=.5", lambda c: c.learning_rate, 0.5),
        ("learning_rate=3", lambda c: c.learning_rate, 3.0),
        ("env.use_gpu=false", lambda c: c.env.use_gpu, False),
        ("env.use_gpu=True", lambda c: c.env.use_gpu, True),
        ("env.seed=null", lambda c: c.env.seed, None),
        ("env.seed=7", lambda c: c.env.seed, 7),
        ("env.backend=warp", lambda c: c.env.backend, "warp"),
        ("init_noise_std=1e-2", lambda c: c.init_noise_std, 0.01),
        ("commands.lin_vel_x=[-2, 2.5]", lambda c: c.commands.lin_vel_x, (-2.0, 2.5)),
        ("commands.heading=[0, 1e-3, 3.14]", lambda c: c.commands.heading, (0.0, 0.001, 3.14)),
        ("tags=[a, b]", lambda c: c.tags, ["a", "b"]),
        ("tags=[]", lambda c: c.tags, []),
        ("name=2024", lambda c: c.name, "2024"),
        ("name=yes", lambda c: c.name, "yes"),
        ("name = trot ", lambda c: c.name, "trot"),
        ("rewards.weights.torques=-2e-4", lambda c: c.rewards.weights["torques"], -2e-4),
        ("rewards.weights.feet_air_time=1", lambda c: c.rewards.weights["feet_air_time"], 1.0),
        ("extras.anything=2.0", lambda c: c.extras, {"anything": 2.0}),  # empty dict: new keys allowed
    ],
)
def test_override_values(override, get, expected):
    value = get(apply_overrides(GaitCfg(), [override]))
    assert value == expected and type(value) is type(expected)


def test_override_mapping_merges():
    cfg = apply_overrides(GaitCfg(), ["env={num_envs: 2, seed: 1}", "rewards.weights={torques: -1.0}"])
    assert cfg.env == EnvCfg(num_envs=2, episode_length_s=15.0, seed=1)
    assert cfg.rewards.weights == {"tracking_lin_vel": 1.5, "torques": -1.0, "feet_air_time": 0.5}


def test_overrides_apply_in_order_and_do_not_mutate():
    original = GaitCfg()
    cfg = apply_overrides(original, ["env.num_envs=8", "env.num_envs=16", "rewards.weights.torques=0.0", "tags=[x]"])
    assert cfg.env.num_envs == 16 and cfg.rewards.weights["torques"] == 0.0 and cfg.tags == ["x"]
    assert original == GaitCfg()
    assert cfg.rewards.weights is not original.rewards.weights


@pytest.mark.parametrize(
    "override, fragments",
    [
        ("env.num_env=5", ["'env.num_env'", "did you mean 'env.num_envs'?", "valid keys in 'env'"]),
        ("evn.num_envs=5", ["'evn'", "did you mean 'env'?", "valid keys at top level"]),
        ("env.zzzzzz=5", ["'env.zzzzzz'", "valid keys in 'env': num_envs"]),
        ("env={num_env: 5}", ["did you mean 'env.num_envs'?"]),
        (
            "rewards.weights.tracking_lin_ve=2.0",
            ["'rewards.weights.tracking_lin_ve'", "did you mean 'rewards.weights.tracking_lin_vel'?",
             "existing keys: tracking_lin_vel, torques, feet_air_time"],
        ),
        ("rewards.weights={torque: 1.0}", ["did you mean 'rewards.weights.torques'?"]),
        ("env.num_envs=lots", ["'env.num_envs'", "expected int", "'lots'"]),
        ("env.num_envs=1.5", ["'env.num_envs'", "expected int", "1.5"]),
        ("env.use_gpu=yes", ["'env.use_gpu'", "expected bool", "true or false"]),
        ("env.use_gpu=1", ["'env.use_gpu'", "expected bool"]),
        ("commands.lin_vel_x=[1, 2, 3]", ["'commands.lin_vel_x'", "2 items"]),
        ("commands.lin_vel_x=-1,1", ["'commands.lin_vel_x'", "[a, b]"]),
        ("env.num_envs", ["malformed override", "section.key=value"]),
        ("=5", ["malformed override", "section.key=value"]),
        ("env..num_envs=5", ["malformed override"]),
        ("env.num_envs.x=5", ["'env.num_envs'", "not a section"]),
        ("tags=[a", ["cannot parse", "tags=[a"]),
    ],
)
def test_override_errors(override, fragments):
    with pytest.raises(ConfigError) as exc:
        apply_overrides(GaitCfg(), [override])
    msg = str(exc.value)
    assert "\n" not in msg
    for fragment in fragments:
        assert fragment in msg, msg


def test_overrides_must_be_a_list():
    with pytest.raises(TypeError):
        apply_overrides(GaitCfg(), "env.num_envs=8")
