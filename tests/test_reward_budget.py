"""tools/reward_budget.py: what a policy is paid for, term by term, at the commands asked for."""

import re

import pytest

from learning import runs
from tools import reward_budget


def test_a_policy_paid_its_phase_rewards_and_one_without_them(capsys):
    coupled, blind = runs.shipped_policy_dir("111", 0), runs.shipped_policy_dir("101", 0)
    assert reward_budget.main([coupled, blind, "--command", "1,0,0", "--robots", "2", "--num_threads", "1"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 2 and all("fell 0 of 2" in line for line in lines)
    terms = [dict((name, float(rate)) for name, rate in re.findall(r"(\w+) ([+-]\d+\.\d+)", line.split(" | ")[3]))
             for line in lines]
    assert terms[0]["stance_grf"] > 0 and terms[0]["swing_grf"] <= 0 and terms[0]["tracking_lin_vel"] > 0
    assert "stance_grf" not in terms[1] and terms[1]["tracking_lin_vel"] > 0  # R = 0: no phase terms at all
    total = float(lines[0].rsplit("sum ", 1)[1])
    assert total == pytest.approx(sum(terms[0].values()), abs=0.01)


def test_a_malformed_command_is_refused_before_anything_is_simulated(capsys):
    with pytest.raises(SystemExit) as exit_info:
        reward_budget.main(["nowhere", "--command", "fly,0"])
    assert exit_info.value.code == 2 and "neither an envelope command" in capsys.readouterr().err
