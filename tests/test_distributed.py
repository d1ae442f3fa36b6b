"""Data-parallel training: train.py under `torchrun --nproc_per_node=2` on CPU processes (gloo).

Every rank logs a digest of its networks after each update (ORCGYM_SYNC_LOG, see
learning.distributed); the tests compare those logs across ranks, across launches and with the
checkpoints rank 0 wrote.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time

import pytest
import torch

from gym_envs.config import ConfigError
from learning import distributed, runs

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TINY = ["--num_envs", "16", "--set", "train.num_steps_per_env=8", "--seed", "3"]
KILL_TIMEOUT_S = 30  # torchrun SIGKILLs ranks that have not exited this long after passing on a Ctrl-C


def torchrun(log_root, sync_log, *args) -> subprocess.Popen:
    cmd = [sys.executable, "-u", "-m", "torch.distributed.run", "--standalone", "--nproc_per_node=2",
           "train.py", "--log_root", str(log_root), *TINY, *args]
    env = {**os.environ, distributed.SYNC_LOG_ENV: str(sync_log), "OMP_NUM_THREADS": "1"}
    return subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def finish(proc: subprocess.Popen) -> str:
    out = proc.communicate(timeout=180)[0]
    assert proc.returncode == 0, out
    return out


def signal_at(proc: subprocess.Popen, pattern: str, signum: int, timeout: float = 120) -> tuple[str, float | None]:
    """Send `signum` when a line of `proc`'s output matches `pattern`; (all its output, when it was sent)."""
    lines, sent = [], None
    for line in proc.stdout:
        lines.append(line)
        if re.search(pattern, line):
            proc.send_signal(signum)
            sent = time.monotonic()
            break
    return "".join(lines) + proc.communicate(timeout=timeout)[0], sent


def sync_logs(folder) -> list[list[tuple[int, str]]]:
    """Per rank: (iteration, network digest) after each update, in order."""
    logs = []
    for rank in (0, 1):
        with open(os.path.join(folder, f"rank{rank}.txt")) as f:
            logs.append([(int(it), digest) for it, digest in (line.split() for line in f)])
    return logs


def checkpoint_digest(run_dir, iteration) -> str:
    data = torch.load(runs.checkpoint_path(run_dir, iteration), weights_only=True)
    assert data["iter"] == iteration
    return distributed.state_digest([data["actor_state_dict"], data["critic_state_dict"]])


def only_run(root) -> str:
    (experiment,) = os.listdir(root)
    (name,) = os.listdir(os.path.join(root, experiment))
    return os.path.join(root, experiment, name)


@pytest.fixture(scope="module")
def two_launches(tmp_path_factory):
    """The same 3-iteration launch twice, each into its own log root."""
    results = []
    for name in ("first", "second"):
        base = tmp_path_factory.mktemp(name)
        out = finish(torchrun(base / "logs", base / "sync", "--task", "mini_cheetah_osc", "--max_iterations", "3",
                            "--num_threads", "1"))
        results.append((base, out))
    return results


def test_ranks_hold_identical_networks_after_every_update(two_launches):
    base, _ = two_launches[0]
    rank0, rank1 = sync_logs(base / "sync")
    assert [it for it, _ in rank0] == [0, 1, 2, 3]
    assert rank0 == rank1
    assert len({digest for _, digest in rank0}) == 4  # each update changed the networks


def test_rank_0_alone_writes_one_run_folder(two_launches):
    base, out = two_launches[0]
    run = only_run(base / "logs")
    assert runs.list_checkpoints(run) == [0, 3]
    assert len([f for f in os.listdir(run) if f.startswith("events.out.tfevents")]) == 1
    assert out.count("run folder ") == 1 and len(re.findall(r"\bit 3/3\b", out)) == 1
    rank0, _ = sync_logs(base / "sync")
    assert checkpoint_digest(run, 0) == rank0[0][1] and checkpoint_digest(run, 3) == rank0[-1][1]


def test_a_second_identical_launch_gives_the_same_networks(two_launches):
    (first, _), (second, _) = two_launches
    assert sync_logs(first / "sync") == sync_logs(second / "sync")
    assert checkpoint_digest(only_run(first / "logs"), 3) == checkpoint_digest(only_run(second / "logs"), 3)


def test_ctrl_c_stops_every_rank_and_resume_continues_on_both(tmp_path):
    logs = tmp_path / "logs"
    proc = torchrun(logs, tmp_path / "sync", "--task", "mini_cheetah_osc", "--max_iterations", "1000")
    out, signalled = signal_at(proc, r"\bit +2/1000", signal.SIGINT)  # what a terminal's Ctrl-C sends to torchrun
    assert signalled is not None, out
    assert time.monotonic() - signalled < KILL_TIMEOUT_S, out  # the ranks exited; torchrun did not kill them
    stopped = re.findall(r"stopped at iteration (\d+); saved", out)
    assert len(stopped) == 1, out
    last = int(stopped[0])
    run = only_run(logs)
    assert runs.list_checkpoints(run)[-1] == last >= 2
    # Without --num_threads each of the two processes gets half the cores.
    env_cfg = runs.load_run_configs(run)[1]
    assert env_cfg.sim.num_threads == max(1, len(os.sched_getaffinity(0)) // 2)
    rank0, rank1 = sync_logs(tmp_path / "sync")
    assert rank0 == rank1 and rank0[-1] == (last, checkpoint_digest(run, last))

    finish(torchrun(logs, tmp_path / "resumed", "--resume", "--max_iterations", "1"))  # one more iteration
    rank0, rank1 = sync_logs(tmp_path / "resumed")
    assert rank0 == rank1 and [it for it, _ in rank0] == [last, last + 1]
    assert rank0[0][1] == checkpoint_digest(run, last)  # both ranks started from the checkpoint


def test_device_choice_and_thread_share_of_many_processes():
    assert distributed.resolve_device(None, distributed.Ranks()) == "cpu"
    assert distributed.thread_share(distributed.Ranks(world_size=512, local_world_size=512)) == 1
    if not torch.cuda.is_available():
        with pytest.raises(ConfigError, match="no CUDA device"):
            distributed.resolve_device("cuda", distributed.Ranks())


def test_sigterm_to_torchrun_stops_every_rank_at_one_iteration_with_a_checkpoint(tmp_path):
    """What a cluster scheduler sends: torchrun passes SIGTERM on to the ranks, which save as for Ctrl-C
    (torchrun itself then exits 1 with its own SignalException, as it does for any SIGTERM)."""
    logs = tmp_path / "logs"
    proc = torchrun(logs, tmp_path / "sync", "--task", "mini_cheetah_osc", "--max_iterations", "1000")
    out, _ = signal_at(proc, r"\bit +2/1000", signal.SIGTERM)
    stopped = re.findall(r"stopped at iteration (\d+); saved", out)
    assert len(stopped) == 1 and "SIGTERM: stopping after this step" in out, out
    last = int(stopped[0])
    run = only_run(logs)
    assert runs.list_checkpoints(run)[-1] == last >= 2
    rank0, rank1 = sync_logs(tmp_path / "sync")
    assert rank0 == rank1 and rank0[-1] == (last, checkpoint_digest(run, last))
