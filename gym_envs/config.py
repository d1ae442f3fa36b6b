"""Typed config utilities over nested dataclasses (task-agnostic).

Configs are plain ``@dataclass`` trees.  This module converts them to and from
plain dicts / YAML and applies command-line overrides of the form
``section.sub.key=value``.  Everything is strict: unknown keys raise a
``ConfigError`` with a did-you-mean suggestion, and values are checked against
the field annotations (``int``, ``float``, ``bool``, ``str``, ``Optional[X]`` /
``X | None``, ``Literal[...]``, ``tuple[X, ...]``, ``tuple[X, Y]``, ``list[X]``,
``dict[str, X]`` and nested dataclasses).

YAML dialect (used by ``load_yaml`` and for override values): YAML 1.1 as in
PyYAML's safe loader, with three fixes so that configs mean what they look like:
  * ``1e-3`` / ``1.5e3`` are floats (PyYAML reads them as strings);
  * only ``true`` / ``false`` are booleans (not ``yes``/``no``/``on``/``off``);
  * integers are plain decimal (``017`` is not octal, ``1:30`` is not 90), and
    dates stay strings.
``save_yaml`` writes floats with ``repr`` precision and quotes any string that
either this loader or a standard YAML loader would read as a non-string, so
files round-trip exactly and stay readable by ``yaml.safe_load``.
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
import functools
import math
import os
import re
import types
import typing
from collections.abc import Mapping
from typing import Any, Literal, Union

import yaml

from gym_envs.files import atomic_write

__all__ = [
    "ConfigError", "to_dict", "from_dict", "apply_overrides", "save_yaml", "load_yaml", "yaml_text",
    "Range", "OneOf", "Ordered", "Check", "check_values",
]


class ConfigError(ValueError):
    """A config problem; the message is one line naming the problem and the fix."""


# --------------------------------------------------------------------------- YAML dialect

_BOOL_TAG = "tag:yaml.org,2002:bool"
_INT_TAG = "tag:yaml.org,2002:int"
_FLOAT_TAG = "tag:yaml.org,2002:float"
_TIMESTAMP_TAG = "tag:yaml.org,2002:timestamp"

_BOOL_RE = re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$")
_INT_RE = re.compile(r"^[-+]?(?:0|[1-9][0-9_]*)$")
_FLOAT_RE = re.compile(
    r"""^(?:[-+]?(?:[0-9][0-9_]*\.[0-9_]*|\.[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)?
          |[-+]?[0-9][0-9_]*[eE][-+]?[0-9]+
          |[-+]?\.(?:inf|Inf|INF)
          |\.(?:nan|NaN|NAN))$""",
    re.X,
)
_EXPONENT_FLOAT_RE = re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$")


class _Loader(yaml.SafeLoader):
    """Safe loader with the config dialect described in the module docstring."""


_Loader.yaml_implicit_resolvers = {
    first: [(tag, rx) for tag, rx in resolvers if tag not in (_BOOL_TAG, _INT_TAG, _FLOAT_TAG, _TIMESTAMP_TAG)]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
_Loader.add_implicit_resolver(_BOOL_TAG, _BOOL_RE, list("tTfF"))
_Loader.add_implicit_resolver(_INT_TAG, _INT_RE, list("-+0123456789"))
_Loader.add_implicit_resolver(_FLOAT_TAG, _FLOAT_RE, list("-+0123456789."))


class _Dumper(yaml.SafeDumper):
    """Safe dumper that also quotes strings like '1e-3' and writes scalar lists inline."""


_Dumper.add_implicit_resolver(_FLOAT_TAG, _EXPONENT_FLOAT_RE, list("-+0123456789"))


def _represent_list(dumper: yaml.SafeDumper, data: list) -> yaml.Node:
    inline = all(isinstance(x, (str, int, float, bool, type(None))) for x in data)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=inline)


_Dumper.add_representer(list, _represent_list)


def _yaml_error_line(err: yaml.YAMLError) -> str:
    mark = getattr(err, "problem_mark", None)
    problem = getattr(err, "problem", None) or str(err).splitlines()[0]
    return f"{problem} at line {mark.line + 1}, column {mark.column + 1}" if mark else problem


# --------------------------------------------------------------------------- helpers


def _join(path: str, key: Any) -> str:
    return f"{path}.{key}" if path else str(key)


def _init_fields(cls: type) -> list[dataclasses.Field]:
    return [f for f in dataclasses.fields(cls) if f.init]


@functools.lru_cache(maxsize=None)
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _is_union(tp: Any) -> bool:
    return typing.get_origin(tp) in (Union, types.UnionType)


def _type_name(tp: Any) -> str:
    if tp is type(None):
        return "None"
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if _is_union(tp):
        return " | ".join(_type_name(a) for a in args)
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in args)
    if origin is not None:
        return f"{origin.__name__}[{', '.join('...' if a is Ellipsis else _type_name(a) for a in args)}]"
    return getattr(tp, "__name__", str(tp))


def _short_repr(value: Any, limit: int = 80) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _type_error(tp: Any, value: Any, key: str) -> ConfigError:
    hint = ""
    if tp is bool or (_is_union(tp) and bool in typing.get_args(tp)):
        hint = " (write true or false)"
    elif isinstance(value, str) and typing.get_origin(tp) in (tuple, list):
        hint = " (write sequences as [a, b])"
    return ConfigError(
        f"invalid value for config key '{key}': expected {_type_name(tp)}, "
        f"got {type(value).__name__} {_short_repr(value)}{hint}"
    )


def _did_you_mean(section: str, key: Any, valid: list[str]) -> str:
    close = difflib.get_close_matches(str(key), valid, n=3, cutoff=0.6)
    return "; did you mean " + " or ".join(repr(_join(section, c)) for c in close) + "?" if close else ""


def _unknown_key(section: str, key: Any, valid: list[str]) -> ConfigError:
    where = f"in '{section}'" if section else "at top level"
    return ConfigError(f"unknown config key '{_join(section, key)}'{_did_you_mean(section, key, valid)} "
                       f"(valid keys {where}: {', '.join(valid) or 'none'})")


# Field metadata for a dict whose keys the config's own validate() checks against another field (a reward stage's
# weights against rewards.weights): overrides may add entries to it, not only change the ones it holds.
OPEN_KEYS = "open_keys"


def _has_open_keys(parent: Any, key: str) -> bool:
    if not dataclasses.is_dataclass(parent):
        return False
    return any(f.name == key and f.metadata.get(OPEN_KEYS) for f in _init_fields(type(parent)))


def _check_dict_key(d: dict, key: Any, path: str) -> None:
    """Typo protection for overrides into a dict field: only existing keys, unless the dict is empty."""
    if d and key not in d:
        valid = [str(k) for k in d]
        raise ConfigError(
            f"unknown key '{_join(path, key)}' in dict '{path}'{_did_you_mean(path, key, valid)} (existing keys: "
            f"{', '.join(valid)}; overrides may only change existing keys - add new ones in the task config class)"
        )


# --------------------------------------------------------------------------- dict conversion


def to_dict(cfg: Any) -> dict:
    """Nested plain-python dict of a dataclass instance (field order; tuples become lists)."""
    if not dataclasses.is_dataclass(cfg) or isinstance(cfg, type):
        raise TypeError(f"to_dict expects a dataclass instance, got {type(cfg).__name__}")
    return _plain(cfg)


def _plain(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name)) for f in _init_fields(type(value))}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    return value


def from_dict(cls: type, data: Mapping, path: str = "", complete: bool = False) -> Any:
    """Build ``cls`` from a nested dict: strict keys, defaults for missing keys, type-checked values.

    A partial nested section is merged onto that field's *default instance*, so a derived task whose
    ``default_factory`` changes section defaults keeps them for keys the dict does not mention; a dict
    field (reward weights, observation scales) keeps its default entries the same way.
    With ``complete`` (a config the program saved, not one a person writes) a missing key, or a missing
    entry of a dict the defaults fill, is an error naming it: the file was cut short or edited.
    """
    return _build(cls, data, path, base=None, complete=complete)


def _field_default(f: dataclasses.Field) -> Any:
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return f.default


def _missing_key(key: str) -> ConfigError:
    return ConfigError(f"config key '{key}' is missing; a saved run config has every key (the file was cut short "
                       f"or edited): restore it from a copy")


def _build(cls: type, data: Mapping, path: str, base: Any, complete: bool = False) -> Any:
    if not (isinstance(cls, type) and dataclasses.is_dataclass(cls)):
        raise TypeError(f"from_dict expects a dataclass type, got {cls!r}")
    if not isinstance(data, Mapping):
        what = f"config section '{path}'" if path else "config"
        raise ConfigError(
            f"{what} must be a mapping of keys to values, got {type(data).__name__} {_short_repr(data)}"
        )
    fields = _init_fields(cls)
    names = [f.name for f in fields]
    for key in data:
        if key not in names:
            raise _unknown_key(path, key, names)
    hints = _hints(cls)
    kwargs = {}
    for f in fields:
        key = _join(path, f.name)
        if f.name not in data:
            if complete:
                raise _missing_key(key)
            if base is not None:
                kwargs[f.name] = copy.deepcopy(getattr(base, f.name))
            elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                raise ConfigError(f"missing required config key '{key}'; add it to the config")
            continue
        value = data[f.name]
        default = getattr(base, f.name) if base is not None else _field_default(f)
        is_section = dataclasses.is_dataclass(default) and not isinstance(default, type)
        if complete and value is None and type(None) not in typing.get_args(hints[f.name]):
            # A file cut right after 'key:' leaves None, which save_yaml never writes there: for a section or a
            # dict, name the first key it lacks.
            entries = [x.name for x in _init_fields(type(default))] if is_section else \
                list(default) if isinstance(default, Mapping) else []
            raise _missing_key(_join(key, entries[0]) if entries else key)
        if isinstance(value, Mapping) and is_section:
            kwargs[f.name] = _build(type(default), value, key, base=default, complete=complete)
        else:
            if isinstance(value, Mapping) and isinstance(default, Mapping):
                for entry in default:
                    if complete and entry not in value:
                        raise _missing_key(_join(key, entry))
                # Entries the file lacks take the defaults, like missing keys: an older run's reward weights
                # then hold the terms added since, at their (neutral) defaults, and save complete again.
                value = {**default, **value}
            kwargs[f.name] = _coerce(hints[f.name], value, key, complete)
    return cls(**kwargs)


def _coerce(tp: Any, value: Any, key: str, complete: bool = False) -> Any:
    """Check ``value`` against annotation ``tp`` and return it converted (int->float, list->tuple, dict->dataclass)."""
    if tp is Any:
        return value
    origin, args = typing.get_origin(tp), typing.get_args(tp)

    if _is_union(tp):
        if value is None and type(None) in args:
            return None
        options = [a for a in args if a is not type(None)]
        if len(options) == 1 and (typing.get_origin(options[0]) or dataclasses.is_dataclass(options[0])):
            return _coerce(options[0], value, key, complete)  # Optional[container]: let it report nested errors itself
        for option in options:
            try:
                return _coerce(option, value, key)
            except ConfigError:
                pass
        raise _type_error(tp, value, key)

    if origin is Literal:
        for allowed in args:
            if type(allowed) is type(value) and allowed == value:
                return allowed
        raise _type_error(tp, value, key)

    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        if isinstance(value, tp):
            return value
        if isinstance(value, Mapping):
            return from_dict(tp, value, key, complete)
        raise _type_error(tp, value, key)

    if tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        raise _type_error(tp, value, key)
    if tp is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        raise _type_error(tp, value, key)

    if tp is tuple or origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise _type_error(tp, value, key)
        if not args:
            return tuple(value)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(args[0], v, f"{key}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(
                f"invalid value for config key '{key}': expected {_type_name(tp)} with {len(args)} items, "
                f"got {len(value)} items {_short_repr(list(value))}"
            )
        return tuple(_coerce(a, v, f"{key}[{i}]") for i, (a, v) in enumerate(zip(args, value)))

    if tp is list or origin is list:
        if not isinstance(value, (list, tuple)):
            raise _type_error(tp, value, key)
        item_tp = args[0] if args else Any
        return [_coerce(item_tp, v, f"{key}[{i}]") for i, v in enumerate(value)]

    if tp is dict or origin is dict:
        if not isinstance(value, Mapping):
            raise _type_error(tp, value, key)
        key_tp, val_tp = args if args else (Any, Any)
        return {
            _coerce(key_tp, k, f"{key} (dict key)"): _coerce(val_tp, v, _join(key, k)) for k, v in value.items()
        }

    if isinstance(tp, type):  # bool, str, None and any other plain type
        if isinstance(value, tp):
            return value
        raise _type_error(tp, value, key)
    raise ConfigError(
        f"unsupported annotation {tp!r} on config key '{key}'; use int, float, bool, str, Optional, "
        f"Literal, tuple, list, dict or a dataclass"
    )


# --------------------------------------------------------------------------- overrides


def _accepts_str(tp: Any) -> bool:
    return tp is str or (_is_union(tp) and str in typing.get_args(tp))


def _dict_value_type(tp: Any) -> Any:
    if _is_union(tp):
        tp = next((a for a in typing.get_args(tp) if a is dict or typing.get_origin(a) is dict), Any)
    args = typing.get_args(tp)
    return args[1] if len(args) == 2 else Any


def _child_type(obj: Any, obj_tp: Any, key: str, path: str, full_key: str, open_keys: bool = False) -> Any:
    """Annotation of ``obj[key]`` / ``obj.key``, raising the did-you-mean error if it does not exist (in a dict
    with ``open_keys``, any key)."""
    if dataclasses.is_dataclass(obj):
        names = [f.name for f in _init_fields(type(obj))]
        if key not in names:
            raise _unknown_key(path, key, names)
        return _hints(type(obj))[key]
    if isinstance(obj, dict):
        if not open_keys:
            _check_dict_key(obj, key, path)
        return _dict_value_type(obj_tp)
    raise ConfigError(
        f"cannot set '{full_key}': '{path}' holds a {type(obj).__name__} value ({_short_repr(obj)}), not a section; "
        f"set '{path}=<value>' instead"
    )


def _assign(parent: Any, key: str, tp: Any, value: Any, path: str) -> None:
    """Set ``parent.key`` (or ``parent[key]``); a mapping value merges into a section / non-empty dict."""
    current = parent.get(key) if isinstance(parent, dict) else getattr(parent, key)
    if isinstance(value, Mapping) and (dataclasses.is_dataclass(current) or (isinstance(current, dict) and current)):
        open_keys = _has_open_keys(parent, key)
        for sub_key, sub_value in value.items():
            sub_path = _join(path, sub_key)
            sub_tp = _child_type(current, tp, sub_key, path, sub_path, open_keys)
            _assign(current, sub_key, sub_tp, sub_value, sub_path)
        return
    new_value = _coerce(tp, value, path)
    if isinstance(parent, dict):
        parent[key] = new_value
    else:
        setattr(parent, key, new_value)


def apply_overrides(cfg: Any, overrides: list[str]) -> Any:
    """Return a deep copy of ``cfg`` with ``section.key=value`` overrides applied (values parsed as YAML).

    For ``str`` fields the text is taken literally unless YAML reads it as a string (so ``name=2024`` is
    ``"2024"``), and ``null`` still means None for Optional[str].  A mapping value (``env={num_envs: 8}``)
    merges into a section or non-empty dict key by key.
    """
    if isinstance(overrides, str):
        raise TypeError("apply_overrides expects a list of 'section.key=value' strings, not a single string")
    new_cfg = copy.deepcopy(cfg)
    for override in overrides:
        key, sep, text = str(override).partition("=")
        parts = key.strip().split(".")
        if not sep or not all(parts):
            raise ConfigError(
                f"malformed override {override!r}; expected the form section.key=value, e.g. env.num_envs=4096"
            )
        text = text.strip()
        try:
            value = yaml.load(text, Loader=_Loader)
        except yaml.YAMLError as err:
            raise ConfigError(
                f"cannot parse the value of override {override!r} as YAML ({_yaml_error_line(err)}); "
                f"quote it or fix the syntax"
            ) from None

        obj, obj_tp, path, open_keys = new_cfg, type(new_cfg), "", False
        for part in parts[:-1]:
            obj_tp = _child_type(obj, obj_tp, part, path, key.strip(), open_keys)
            open_keys = _has_open_keys(obj, part)
            obj = obj[part] if isinstance(obj, dict) else getattr(obj, part)
            path = _join(path, part)
        leaf_tp = _child_type(obj, obj_tp, parts[-1], path, key.strip(), open_keys)
        if _accepts_str(leaf_tp) and not isinstance(value, str) and not (value is None and _is_union(leaf_tp)):
            value = text
        _assign(obj, parts[-1], leaf_tp, value, _join(path, parts[-1]))
    return new_cfg


# --------------------------------------------------------------------------- YAML files


def yaml_text(data: Any) -> str:
    """A config (dataclass instance) or plain data as YAML text in the dialect ``load_yaml`` reads."""
    if dataclasses.is_dataclass(data) and not isinstance(data, type):
        data = to_dict(data)
    return yaml.dump(data, Dumper=_Dumper, sort_keys=False, default_flow_style=False, allow_unicode=True)


def save_yaml(cfg: Any, path: str | os.PathLike) -> None:
    """Validate ``cfg`` and write it as YAML atomically (temp file in the same directory, then os.replace)."""
    path = os.fspath(path)
    # Round-trip through from_dict first: a config that load_yaml would reject is refused here, not at load time.
    text = yaml_text(from_dict(type(cfg), to_dict(cfg)))
    with atomic_write(path) as f:
        f.write(text)


def load_yaml(cls: type, path: str | os.PathLike, complete: bool = False) -> Any:
    """Load a YAML file written by ``save_yaml`` (or by hand) into ``cls``; errors name the file.

    ``complete``: the file was written by ``save_yaml`` and must hold every key (see ``from_dict``).
    """
    path = os.fspath(path)
    with open(path, encoding="utf-8") as f:
        try:
            data = yaml.load(f, Loader=_Loader)
        except yaml.YAMLError as err:
            raise ConfigError(f"{path}: invalid YAML ({_yaml_error_line(err)}); fix the syntax") from None
    try:
        return from_dict(cls, {} if data is None else data, complete=complete)
    except ConfigError as err:
        raise ConfigError(f"{path}: {err}") from None


# --------------------------------------------------------------------------- value checks
# Types are checked when a config is built or overridden; these rules check what the values mean.
# A rule is a callable: value -> None when allowed, else the text "what is allowed".


def _leaves(value: Any, path: str = ""):
    """(key, value) of every scalar inside plain config data: dict values and list or tuple items, depth first."""
    if isinstance(value, Mapping):
        for k, v in value.items():
            yield from _leaves(v, _join(path, k))
    elif isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            yield from _leaves(v, f"{path}[{i}]")
    else:
        yield path, value


def _numbers(value: Any) -> list:
    """Every number inside a value (scalars, tuples, lists, dict values), bools excluded."""
    return [v for _, v in _leaves(value) if isinstance(v, (int, float)) and not isinstance(v, bool)]


@dataclasses.dataclass(frozen=True)
class Range:
    """Every number in the value lies in [low, high] (open ends when low_open / high_open)."""

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False

    def allows(self, x: float) -> bool:
        if self.low is not None and (x <= self.low if self.low_open else x < self.low):
            return False
        return self.high is None or (x < self.high if self.high_open else x <= self.high)

    def describe(self) -> str:
        if self.low is not None and self.high is not None:
            left, right = "(" if self.low_open else "[", ")" if self.high_open else "]"
            return f"a number in {left}{self.low:g}, {self.high:g}{right}"
        if self.low is not None:
            return f"a number {'>' if self.low_open else '>='} {self.low:g}"
        return f"a number {'<' if self.high_open else '<='} {self.high:g}"

    def __call__(self, value: Any) -> str | None:
        return None if all(self.allows(x) for x in _numbers(value)) else self.describe()


@dataclasses.dataclass(frozen=True)
class OneOf:
    values: tuple

    def __call__(self, value: Any) -> str | None:
        return None if value in self.values else "one of " + ", ".join(map(str, self.values))


@dataclasses.dataclass(frozen=True)
class Ordered:
    """A (low, high) pair with low <= high, or a tuple of such pairs."""

    def __call__(self, value: Any) -> str | None:
        pairs = value if value and isinstance(value[0], (list, tuple)) else [value]
        return None if all(lo <= hi for lo, hi in pairs) else "a range [low, high] with low <= high"


@dataclasses.dataclass(frozen=True)
class Check:
    """Any other rule: `test(value)` is True when the value is allowed; `allowed` says what is."""

    test: Any  # Callable[[Any], bool]
    allowed: str

    def __call__(self, value: Any) -> str | None:
        return None if self.test(value) else self.allowed


def _lookup(data: Any, key: str) -> Any:
    """The value at a dotted key; None when a section on the way is None (an optional section left out)."""
    for part in key.split("."):
        if data is None:
            return None
        data = data[part]
    return data


def check_values(cfg: Any, rules: Mapping[str, Any], prefix: str = "") -> None:
    """Every float finite and every ``rules[key]`` satisfied, else a one-line ConfigError naming the key.

    ``prefix`` is put before key names in messages (``train.`` for the train config).
    """
    data = to_dict(cfg)
    found = next(((k, v) for k, v in _leaves(data) if isinstance(v, float) and not math.isfinite(v)), None)
    if found:
        raise ConfigError(f"config key '{prefix}{found[0]}' is {found[1]}; allowed: a finite number")
    for key, rule in rules.items():
        value = _lookup(data, key)
        if value is None:
            continue
        # A rule on a dict applies to each of its values, so the message names the entry.
        entries = [(_join(key, k), v) for k, v in value.items()] if isinstance(value, Mapping) else [(key, value)]
        for name, entry in entries:
            for one in rule if isinstance(rule, tuple) else (rule,):
                allowed = one(entry)
                if allowed:
                    raise ConfigError(f"config key '{prefix}{name}' is {_short_repr(entry)}; allowed: {allowed}")
