"""The ORC ablation string: which of phase Observations, phase Rewards and Coupling are on."""

from __future__ import annotations

import warnings
from typing import NamedTuple

from gym_envs.config import ConfigError

# The configurations of the paper; 001 is left out there because it equals 000.
PAPER_CONFIGURATIONS = ("000", "100", "101", "010", "110", "011", "111")


class ORC(NamedTuple):
    observations: bool
    rewards: bool
    coupling: bool

    def __str__(self) -> str:
        return "".join("1" if on else "0" for on in self)


ORC_FORMAT = "three digits of 0/1 for Observations, Rewards, Coupling, e.g. 111"


def is_orc_string(text) -> bool:
    return isinstance(text, str) and len(text) == 3 and not set(text) - {"0", "1"}


def parse_orc(text: str) -> ORC:
    """'110' -> ORC(True, True, False). Anything but three 0/1 digits is an error."""
    if not is_orc_string(text):
        raise ConfigError(f"malformed ORC string {text!r}; use {ORC_FORMAT}")
    return ORC(*(c == "1" for c in text))


def parse_training_orc(text: str) -> ORC:
    """parse_orc for a configuration someone chose to train: 001 gets a warning that it equals 000.

    Evaluations that switch coupling on for a C = 0 policy reach 001 deliberately and use parse_orc.
    """
    orc = parse_orc(text)
    if text == "001":
        warnings.warn(
            "ORC 001 equals 000: without phase observations or phase rewards the oscillators cannot "
            "affect the policy, so coupling alone changes nothing",
            stacklevel=2,
        )
    return orc
