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


def test_the_first_checkpoint_meeting_both_goals_is_named_with_its_training_time(tmp_path):
    import train
    from learning import runs

    assert train.main(["--task", "mini_cheetah_osc", "--log_root", str(tmp_path), "--max_iterations", "2",
                       "--num_envs", "16", "--num_threads", "1", "--headless", "--set",
                       "train.num_steps_per_env=4"]) == 0
    (run,) = [p.parent for p in tmp_path.glob("*/*/train.yaml")]
    minutes = runs.training_seconds(str(run), until=2) / 60
    assert evaluate_checkpoints.first_met_line(str(run), [2]).startswith(
        f"first checkpoint meeting both goals: it 2, {minutes:.1f} min of training")
    assert evaluate_checkpoints.first_met_line(str(run), []).endswith("none of those measured")
