"""tools/evaluate_checkpoints.py's command line: bad input gets one clear error before anything is simulated."""

import pytest

from tools import evaluate_checkpoints


def test_confirm_seed_equal_to_the_evaluation_seed_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        evaluate_checkpoints.main([str(tmp_path), "--seed", "3", "--confirm_seed", "3"])
    assert exit_info.value.code == 2
    assert "--confirm_seed 3 is the evaluation seed" in capsys.readouterr().err


def test_a_run_without_the_wanted_checkpoints_is_named(tmp_path, capsys):
    assert evaluate_checkpoints.main([str(tmp_path), "--checkpoints", "700"]) == 1
    err = capsys.readouterr().err
    assert "no checkpoints [700]" in err and str(tmp_path) in err
