"""tools/fall_rate.py: falls at one envelope command, counted on as many robots as asked."""

import pytest

from learning import runs
from tools import fall_rate


def test_a_shipped_policy_standing_keeps_its_robots_up(capsys):
    policy = runs.shipped_policy_dir("111", 0)
    assert fall_rate.main([policy, "--robots", "4", "--num_threads", "1"]) == 0
    (line,) = capsys.readouterr().out.splitlines()
    assert line.startswith(f"{policy} | stand | fell 0 of 4 (0.0 %)")


def test_an_unknown_command_is_refused_before_anything_is_simulated(capsys):
    with pytest.raises(SystemExit) as exit_info:
        fall_rate.main(["nowhere", "--command", "fly"])
    assert exit_info.value.code == 2 and "invalid choice: 'fly'" in capsys.readouterr().err
