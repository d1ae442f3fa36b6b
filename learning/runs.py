"""Run folders, checkpoints and finding them again.

Layout (one folder per training run; a resumed run gets a new folder):

    <log_root>/<experiment>/<YYYY-mm-dd_HH-MM-SS>_<run>/
        env.yaml         full env config, as built (gym_envs.config.save_yaml)
        train.yaml       full train config, including the task name and the seed
        model_<it>.pt    checkpoints; <it> = PPO iterations completed when it was written
        events.out.tfevents.*   tensorboard scalars, step = iteration index
        git/             state of the repository the run was started from
        exported/        policy.pt (TorchScript) and policy.onnx, written by play.py --export

        format.yaml      the run-folder format that wrote it (RUN_FORMAT; absent in older runs)
        .lock            flock-ed by the process writing the folder (see FolderLock)

Checkpoints are written atomically (temporary file in the same folder, then os.replace) and read
with `torch.load(weights_only=True)`: they hold only tensors, dicts, lists, numbers and strings,
and every tensor must be finite. The hidden temporary file a killed save leaves behind is removed
by the next save into that folder, and by train.py when it resumes from the folder, but only when
no process holds the folder's lock: a live run is never touched.
Every failure here is a `RunError` whose message is one line saying what exists.
"""

from __future__ import annotations

import datetime
import fcntl
import glob
import os
import pickle
import re
import sys
from dataclasses import dataclass
from typing import Any

import torch
import yaml

from gym_envs.config import ConfigError, load_yaml
from gym_envs.files import atomic_write
from gym_envs.legged_robot_config import REPO_ROOT

DEFAULT_LOG_ROOT = os.path.join(REPO_ROOT, "logs")
POLICY_ROOT = os.path.join(REPO_ROOT, "resources", "policies")
ENV_YAML, TRAIN_YAML = "env.yaml", "train.yaml"
EXPORT_DIR = "exported"
FORMAT_YAML = "format.yaml"
LOCK_FILE = ".lock"
# The run-folder format this code writes. Format 1: env.yaml and train.yaml hold every config key, so a
# missing key is an error. Folders without format.yaml (format 0, written before) take the defaults for
# keys they lack. Adding a config key makes older folders lack it: bump this then, so they stay loadable
# (tests/test_reliability.py holds the keys' digest per format and fails until it is bumped).
# Format 2: sim.cuda_graphs. Format 3: rewards.tracking_error. Format 4: rewards.second_stage,
# osc.uncoupled_gait_weights. Format 5: osc.second_stage. Format 6: osc.uncoupled_commands.
# Format 7: rewards.weights.swing_contact (a new reward term, 0 by default). Format 8:
# train.obs_normalization_frozen_from. Format 9: osc.phase_rewards_standing.
RUN_FORMAT = 9
# What format-0 runs trained with where a key added since defaults to something else: the yaw-rate term
# became the paper's squared exponential together with the key that names it (issue 26).
FORMAT_0_VALUES = {ENV_YAML: {"rewards.yaw_tracking": "released_quartic"}}

_CHECKPOINT_RE = re.compile(r"^model_(\d+)\.pt$")
_GIT_SECTION_RE = re.compile(r"--- git (\w+) ---\n(.*?)(?=\n--- git |\Z)", re.S)
_TIMESTAMP_FORMAT = "%Y-%m-%d_%H-%M-%S"
_TIMESTAMP_LEN = len("2000-01-01_00-00-00")


class RunError(ConfigError):
    """A run, checkpoint or checkpoint content that does not exist or does not fit; one line."""


def default_log_root() -> str:
    return os.environ.get("ORCGYM_LOG_ROOT") or DEFAULT_LOG_ROOT  # set but empty counts as unset


# --- who writes a folder ------------------------------------------------------------------------


class FolderLock:
    """This process writes `folder`: an exclusive flock on <folder>/.lock, holding the pid and program.

    The kernel drops the lock when the process ends, however it ends, so a killed run leaves no stale
    lock. A second writer (a resume cleaning up, a second sweep into the same folder) gets a RunError
    naming the holder's pid; `fix` says what to do instead.
    """

    def __init__(self, folder: str, fix: str):
        path = os.path.join(folder, LOCK_FILE)
        self.fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _lock_holder(self.fd)
            os.close(self.fd)
            raise RunError(f"{folder} is being written by {holder}; {fix}") from None
        os.ftruncate(self.fd, 0)
        os.write(self.fd, f"{os.getpid()} {os.path.basename(sys.argv[0]) if sys.argv else 'python'}\n".encode())

    def release(self) -> None:
        if self.fd is not None:
            os.close(self.fd)  # closing the only descriptor drops the flock
            self.fd = None

    def __enter__(self) -> FolderLock:
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def _lock_holder(fd: int) -> str:
    """'process <pid> (<program>)' from a lock file's contents."""
    text = os.pread(fd, 200, 0).decode(errors="replace").split()
    if not text:
        return "another process"
    return f"process {text[0]}" + (f" ({text[1]})" if len(text) > 1 else "")


def check_not_in_use(folder: str, fix: str) -> None:
    """RunError naming the holder's pid if a process writes `folder` now; creates nothing.

    A shared flock, released at once: it conflicts only with a writer's exclusive one, so processes
    that all merely check (the ranks of one torchrun) do not see each other.
    """
    try:
        fd = os.open(os.path.join(folder, LOCK_FILE), os.O_RDONLY)
    except FileNotFoundError:
        return  # never locked: nobody writes it
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        raise RunError(f"{folder} is being written by {_lock_holder(fd)}; {fix}") from None
    finally:
        os.close(fd)


# --- creating runs ----------------------------------------------------------------------------


def check_folder_names(experiment: str, run_name: str) -> None:
    if not experiment:
        raise RunError("the experiment name is empty")
    for name in (experiment, run_name):
        if os.sep in name or name in (".", ".."):
            raise RunError(f"experiment and run names must be plain folder names, got {name!r}")


def create_run_dir(log_root: str, experiment: str, run_name: str) -> str:
    """Make a new, empty run folder; a name taken in the same second gets a -2, -3... suffix."""
    check_folder_names(experiment, run_name)
    parent = os.path.join(log_root, experiment)
    os.makedirs(parent, exist_ok=True)
    stamp = datetime.datetime.now().strftime(_TIMESTAMP_FORMAT)
    base = f"{stamp}_{run_name}" if run_name else stamp
    for suffix in range(1, 1000):
        path = os.path.join(parent, base if suffix == 1 else f"{base}-{suffix}")
        try:
            os.mkdir(path)
            return path
        except FileExistsError:
            continue
    raise RunError(f"cannot create a run folder under {parent}: too many runs named {base}")


# --- checkpoints ------------------------------------------------------------------------------


def checkpoint_path(run_dir: str, iteration: int) -> str:
    return os.path.join(run_dir, f"model_{iteration}.pt")


def list_checkpoints(run_dir: str) -> list[int]:
    """Iterations of the model_<it>.pt files in run_dir, ascending."""
    return sorted(int(m.group(1)) for m in map(_CHECKPOINT_RE.match, os.listdir(run_dir)) if m)


def checkpoint_iteration(path: str) -> int:
    """The iteration in a model_<it>.pt file name."""
    m = _CHECKPOINT_RE.match(os.path.basename(path))
    if not m:
        raise RunError(f"{path} is not named model_<iteration>.pt")
    return int(m.group(1))


def remove_stale_temps(run_dir: str) -> list[str]:
    """Delete the hidden `.model_<it>.pt.*.tmp` files that saves killed mid-write leave; returns their paths.

    Call it as the folder's writer (holding its FolderLock, or as the only process that writes it): a
    temporary file present before that process saves is then stale.
    """
    stale = glob.glob(os.path.join(glob.escape(run_dir), ".model_*.pt.*.tmp"))
    for path in stale:
        os.remove(path)
    return stale


def remove_stale_temps_of_idle_run(run_dir: str, fix: str) -> list[str]:
    """remove_stale_temps of a folder this process does not write, if no process writes it (else RunError)."""
    if not glob.glob(os.path.join(glob.escape(run_dir), ".model_*.pt.*.tmp")):
        return []  # nothing to remove: leave the folder exactly as it is (no lock file either)
    with FolderLock(run_dir, fix):
        return remove_stale_temps(run_dir)


def save_checkpoint(data: dict, path: str) -> None:
    """torch.save to a temporary file beside `path`, then os.replace: readers never see half a file."""
    remove_stale_temps(os.path.dirname(os.path.abspath(path)))
    with atomic_write(path, binary=True) as f:
        torch.save(data, f)


_DISALLOWED_GLOBAL_RE = re.compile(r"unsupported GLOBAL (\S+)|Unsupported global: GLOBAL (\S+)")


def load_checkpoint(path: str, map_location: str | torch.device | None = None) -> dict:
    if not os.path.isfile(path):
        raise RunError(f"checkpoint {path} does not exist")
    try:
        data = torch.load(path, map_location=map_location, weights_only=True)
    except pickle.UnpicklingError as err:  # weights_only refused an object that is not plain data
        found = _DISALLOWED_GLOBAL_RE.search(str(err))
        what = next(g for g in found.groups() if g) if found else "an object that is not plain data"
        raise RunError(
            f"refused checkpoint {path}: it holds {what}, and loading it could run code (orcgym checkpoints hold "
            f"only tensors, numbers, strings, lists and dicts); use a checkpoint that orcgym wrote"
        ) from None
    except Exception as err:  # a truncated file, not a torch file
        raise RunError(f"cannot read checkpoint {path}: the file is truncated or not a torch checkpoint "
                       f"({type(err).__name__}: {' '.join(str(err).split())})") from None
    if not isinstance(data, dict) or "actor_state_dict" not in data:
        raise RunError(f"{path} is not an orcgym/rsl-rl checkpoint (no actor_state_dict)")
    bad = non_finite_tensor(data)
    if bad:
        folder = os.path.dirname(os.path.abspath(path))
        others = [it for it in list_checkpoints(folder) if checkpoint_path(folder, it) != os.path.abspath(path)]
        raise RunError(f"refused checkpoint {path}: tensor {bad[0]} holds {bad[1]} NaN or infinite values (training "
                       f"diverged before this save); remove it, or pick an earlier one with play.py/train.py "
                       f"--checkpoint N" + (f" (its run also has {', '.join(map(str, others))})" if others else ""))
    return data


def non_finite_tensor(data: Any, name: str = "") -> tuple[str, int] | None:
    """(dotted name, count) of the first floating-point tensor in nested dicts/lists with a NaN or infinity."""
    if isinstance(data, torch.Tensor):
        count = int((~torch.isfinite(data)).sum()) if data.is_floating_point() else 0
        return (name, count) if count else None
    items = data.items() if isinstance(data, dict) else enumerate(data) if isinstance(data, (list, tuple)) else ()
    for key, value in items:
        found = non_finite_tensor(value, f"{name}.{key}" if name else str(key))
        if found:
            return found
    return None


def model_io_dims(state_dict: dict) -> tuple[int, int]:
    """(input size, output size) of an MLP model's state dict: its first and last linear layers."""
    weights = [v for k, v in state_dict.items() if k.endswith("weight") and getattr(v, "ndim", 0) == 2]
    if not weights:
        raise RunError("checkpoint model has no linear layers")
    return int(weights[0].shape[1]), int(weights[-1].shape[0])


def check_checkpoint_fits(
    data: dict, path: str, actor_obs: int, critic_obs: int, num_actions: int, context: str, cause: str = ""
) -> None:
    """Raise a RunError naming the sizes if the checkpoint's networks do not fit the task's."""
    ckpt_actor, ckpt_actions = model_io_dims(data["actor_state_dict"])
    ckpt_critic = model_io_dims(data["critic_state_dict"])[0] if "critic_state_dict" in data else critic_obs
    if (ckpt_actor, ckpt_critic) != (actor_obs, critic_obs):
        hint = cause or "the observation terms differ (observations.actor/critic overrides or another task)"
        raise RunError(
            f"checkpoint {path} expects {ckpt_actor} actor / {ckpt_critic} critic observations but {context} gives "
            f"{actor_obs} / {critic_obs}; likely cause: {hint}"
        )
    if ckpt_actions != num_actions:
        raise RunError(f"checkpoint {path} outputs {ckpt_actions} actions but {context} has {num_actions}")


def check_layer_shapes(data: dict, path: str, models: dict[str, torch.nn.Module], context: str) -> None:
    """Raise a RunError naming the first layer whose shape (or presence) differs between checkpoint and models.

    models: checkpoint key (e.g. "actor_state_dict") -> the model it is loaded into. Called after
    `check_checkpoint_fits`, so a difference here is in the hidden layers or the model layout.
    """
    for key, model in models.items():
        if key not in data:
            continue
        saved, wanted = data[key], model.state_dict()
        part = key.removesuffix("_state_dict")
        for name in list(wanted) + [n for n in saved if n not in wanted]:
            a = tuple(saved[name].shape) if name in saved else None
            b = tuple(wanted[name].shape) if name in wanted else None
            if a != b:
                raise RunError(
                    f"checkpoint {path} does not fit {context}: {part} layer {name} is {list(a) if a else 'absent'} "
                    f"there but {list(b) if b else 'absent'} here; likely cause: other train.{part}.hidden_dims "
                    f"(the checkpoint's: {hidden_dims(saved)}, configured: {hidden_dims(wanted)}); the configured "
                    f"ones come from the run's train.yaml and any --profile or --set given now"
                )


def hidden_dims(state_dict: dict) -> list[int]:
    """Hidden layer widths of an MLP state dict: the outputs of every linear layer but the last."""
    weights = [v for k, v in state_dict.items() if k.endswith("weight") and getattr(v, "ndim", 0) == 2]
    return [int(w.shape[0]) for w in weights[:-1]]


# --- finding runs -----------------------------------------------------------------------------


@dataclass
class RunInfo:
    path: str
    experiment: str
    name: str

    def read_yaml(self, name: str) -> dict:
        """The YAML as plain data (for filtering); {} if missing or unreadable."""
        try:
            return self._load_yaml(name)
        except (OSError, yaml.YAMLError):
            return {}

    def _load_yaml(self, name: str) -> dict:
        with open(os.path.join(self.path, name), encoding="utf-8") as f:
            data = yaml.safe_load(f)
        if not isinstance(data, dict):
            raise yaml.YAMLError("not a mapping of keys to values")
        return data

    def unreadable(self) -> str:
        """Why its env.yaml or train.yaml cannot be read ('' when both can)."""
        for name in (ENV_YAML, TRAIN_YAML):
            try:
                self._load_yaml(name)
            except (OSError, yaml.YAMLError) as err:
                return f"{name}: {str(err).splitlines()[0] if str(err) else type(err).__name__}"
        return ""

    @property
    def task(self) -> str | None:
        return self.read_yaml(TRAIN_YAML).get("task")

    @property
    def orc(self) -> str | None:
        osc = self.read_yaml(ENV_YAML).get("osc")
        return str(osc.get("orc")) if isinstance(osc, dict) else None

    def sort_key(self) -> tuple:
        stamp = self.name[:_TIMESTAMP_LEN]
        try:
            created = os.stat(os.path.join(self.path, ENV_YAML)).st_mtime_ns
        except OSError:
            created = 0
        return (stamp, created, self.name)


def is_run_dir(path: str) -> bool:
    return os.path.isfile(os.path.join(path, ENV_YAML)) and os.path.isfile(os.path.join(path, TRAIN_YAML))


def list_runs(log_root: str, experiment: str | None = None) -> list[RunInfo]:
    """Run folders (those with env.yaml and train.yaml), oldest first."""
    if not os.path.isdir(log_root):
        return []
    experiments = [experiment] if experiment else sorted(os.listdir(log_root))
    runs = []
    for exp in experiments:
        exp_dir = os.path.join(log_root, exp)
        if not os.path.isdir(exp_dir):
            continue
        for name in os.listdir(exp_dir):
            path = os.path.join(exp_dir, name)
            if is_run_dir(path):
                runs.append(RunInfo(path, exp, name))
    return sorted(runs, key=RunInfo.sort_key)


def scan_runs(root: str, depth: int = 2) -> tuple[list[str], list[tuple[str, str]]]:
    """Run folders at root or at most `depth` levels below it, sorted by path, and the folders there that
    hold part of a run (env.yaml, train.yaml or a checkpoint) but not all of it, each with what it lacks."""
    names = set(os.listdir(root))
    parts = {ENV_YAML: ENV_YAML in names, TRAIN_YAML: TRAIN_YAML in names,
             "a checkpoint model_<it>.pt": any(_CHECKPOINT_RE.match(n) for n in names)}
    if any(parts.values()):
        missing = [part for part, present in parts.items() if not present]
        return ([], [(os.path.abspath(root), "no " + " and no ".join(missing))]) if missing else \
            ([os.path.abspath(root)], [])
    found: list[str] = []
    skipped: list[tuple[str, str]] = []
    if depth > 0:
        for name in sorted(names):
            sub = os.path.join(root, name)
            if os.path.isdir(sub):
                more, less = scan_runs(sub, depth - 1)
                found += more
                skipped += less
    return found, skipped


def _describe(runs: list[RunInfo], limit: int = 8) -> str:
    if not runs:
        return "none"
    names = [f"{r.experiment}/{r.name}" for r in runs[-limit:]]
    more = f" (and {len(runs) - limit} older)" if len(runs) > limit else ""
    return ", ".join(names) + more


def find_run(
    log_root: str,
    load_run: str | None = None,
    experiment: str | None = None,
    task: str | None = None,
    orc: str | None = None,
) -> str:
    """The run folder to load.

    load_run: a path to a run folder, or the name of a run folder (searched in `experiment`, or in
    every experiment); None or '-1' takes the newest run (that has a checkpoint) matching the
    experiment, task and ORC filters.
    """
    where = os.path.join(log_root, experiment) if experiment else log_root
    if load_run and load_run != "-1":
        if os.path.isdir(load_run):
            if not is_run_dir(load_run):
                raise RunError(f"{load_run} is not a run folder (it needs {ENV_YAML} and {TRAIN_YAML})")
            return os.path.abspath(load_run)
        candidates = [r for r in list_runs(log_root, experiment) if r.name == load_run]
        if len(candidates) == 1:
            return candidates[0].path
        if len(candidates) > 1:
            raise RunError(
                f"run {load_run!r} exists in several experiments under {where} "
                f"({', '.join(r.experiment for r in candidates)}); pass --experiment_name or a path"
            )
        runs = [r for r in list_runs(log_root, experiment) if (task is None or r.task == task)]
        raise RunError(f"no run {load_run!r} under {where}; existing runs: {_describe(runs)}")

    runs = list_runs(log_root, experiment)
    matching = [
        r for r in runs
        if (task is None or r.task == task) and (orc is None or r.orc == orc) and list_checkpoints(r.path)
    ]
    if task is not None or orc is not None:
        # A newer run that cannot be read might be the one meant: say so rather than pass over it.
        newer = runs[runs.index(matching[-1]) + 1:] if matching else runs
        for r in reversed(newer):
            why = r.unreadable() if list_checkpoints(r.path) else ""
            if why:
                raise RunError(f"the newest run {r.path} cannot be read ({why}); fix or remove it, or choose a run "
                               f"with --load_run")
    if not matching:
        wanted = " ".join(f for f in (f"task={task}" if task else "", f"orc={orc}" if orc else "") if f)
        raise RunError(
            f"no run with a checkpoint under {where}" + (f" for {wanted}" if wanted else "")
            + f"; existing runs: {_describe(runs)}"
        )
    return matching[-1].path


def find_checkpoint(run_dir: str, checkpoint: int = -1) -> str:
    """Path of model_<checkpoint>.pt in run_dir; -1 is the highest iteration."""
    available = list_checkpoints(run_dir)
    if not available:
        raise RunError(f"run {run_dir} has no checkpoints (model_<iteration>.pt)")
    if checkpoint == -1:
        return checkpoint_path(run_dir, available[-1])
    if checkpoint not in available:
        raise RunError(
            f"run {run_dir} has no checkpoint {checkpoint}; available iterations: {', '.join(map(str, available))}"
        )
    return checkpoint_path(run_dir, checkpoint)


def shipped_policy_dir(orc: str, seed: int = 0, root: str | None = None) -> str:
    """resources/policies/ORC_<xyz>/seed<k>/: one folder per configuration and training seed (seed 0 is the
    policy play and the single-policy examples use)."""
    return os.path.join(root or POLICY_ROOT, f"ORC_{orc}", f"seed{seed}")


def is_shipped(run_dir: str) -> bool:
    return os.path.commonpath([os.path.abspath(run_dir), POLICY_ROOT]) == POLICY_ROOT


def export_dir(run_dir: str, log_root: str) -> str:
    """Where exports of a run go: <run>/exported, and for a shipped policy <log_root>/shipped/ORC_<xyz>/seed<k>/exported
    (resources/ stays as the repository has it)."""
    if is_shipped(run_dir):
        return os.path.join(log_root, "shipped", os.path.relpath(os.path.abspath(run_dir), POLICY_ROOT), EXPORT_DIR)
    return os.path.join(run_dir, EXPORT_DIR)


def training_seconds(run_dir: str, until: int | None = None, resumed_chain: bool = True) -> float | None:
    """Seconds a train.py run spent training (env stepping and PPO updates, as its TensorBoard events record
    them) in its iterations before `until`, plus, with `resumed_chain`, those of the run it was resumed from, up
    to that checkpoint; None where a run of the chain has no such record."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator  # slow to import: here only

    accumulator = EventAccumulator(run_dir, size_guidance={"scalars": 0})
    accumulator.Reload()
    tags = ("Perf/collection_time", "Perf/learning_time")
    if not set(tags) <= set(accumulator.Tags()["scalars"]):
        return None
    seconds = sum(e.value for tag in tags for e in accumulator.Scalars(tag) if until is None or e.step < until)
    resumed_from = load_run_configs(run_dir)[2].resumed_from
    if not resumed_from or not resumed_chain:
        return seconds
    earlier = os.path.dirname(resumed_from)
    if not is_run_dir(earlier):
        return None
    before = training_seconds(earlier, until=checkpoint_iteration(resumed_from))
    return None if before is None else seconds + before


def trained_commit(run_dir: str) -> str | None:
    """The short commit a run was trained at, from the code state rsl-rl's logger stores in <run>/git/;
    '+diff' marks a run trained with uncommitted changes. None when the run has no such record."""
    for path in sorted(glob.glob(os.path.join(run_dir, "git", "*.diff"))):
        with open(path) as f:
            sections = dict(_GIT_SECTION_RE.findall(f.read()))
        commit = sections.get("commit", "").strip()
        if commit:
            return commit[:7] + ("+diff" if sections.get("diff", "").strip() else "")
    return None


def run_task(run_dir: str) -> str | None:
    """The task a run trained, from its train.yaml."""
    return RunInfo(run_dir, os.path.basename(os.path.dirname(run_dir)), os.path.basename(run_dir)).task


def save_run_configs(run_dir: str, env_cfg: Any, train_cfg: Any) -> None:
    """env.yaml and train.yaml (every key) and format.yaml of a run folder this process writes."""
    from gym_envs.config import save_yaml

    save_yaml(env_cfg, os.path.join(run_dir, ENV_YAML))
    save_yaml(train_cfg, os.path.join(run_dir, TRAIN_YAML))
    with atomic_write(os.path.join(run_dir, FORMAT_YAML)) as f:
        f.write(f"run_format: {RUN_FORMAT}\n")


def run_format(run_dir: str) -> int:
    """The format a run folder was written in (0: before format.yaml existed)."""
    path = os.path.join(run_dir, FORMAT_YAML)
    if not os.path.isfile(path):
        return 0
    try:
        with open(path, encoding="utf-8") as f:
            data = yaml.safe_load(f)
    except (OSError, yaml.YAMLError):
        data = None
    value = data.get("run_format") if isinstance(data, dict) else None
    if not isinstance(value, int) or isinstance(value, bool) or value < 1:
        raise RunError(f"{path} cannot be read; it holds one line 'run_format: {RUN_FORMAT}' (restore it, or remove "
                       f"it if the run was written before run formats existed)")
    if value > RUN_FORMAT:
        raise RunError(f"{run_dir} was written by a newer orcgym (run format {value}; this one reads formats up to "
                       f"{RUN_FORMAT}); update orcgym to use it")
    return value


def load_run_yaml(run_dir: str, cls: type, name: str) -> Any:
    """env.yaml or train.yaml of a run folder as `cls`. A folder of this code's format must hold every key
    (a missing one is an error naming it); an older one takes the defaults for keys added since, or what
    it trained with where that differs (FORMAT_0_VALUES)."""
    from gym_envs.config import apply_overrides

    path, version = run_file(run_dir, name), run_format(run_dir)
    cfg = load_yaml(cls, path, complete=version == RUN_FORMAT)
    if version == 0:
        with open(path, encoding="utf-8") as f:
            saved = yaml.safe_load(f) or {}
        cfg = apply_overrides(cfg, [f"{key}={value}" for key, value in FORMAT_0_VALUES.get(name, {}).items()
                                    if not _holds_key(saved, key)])
    return cfg


def _holds_key(data: dict, dotted: str) -> bool:
    for part in dotted.split("."):
        if not isinstance(data, dict) or part not in data:
            return False
        data = data[part]
    return True


def run_file(run_dir: str, name: str) -> str:
    """The path of env.yaml or train.yaml of a run folder; RunError if it is missing."""
    path = os.path.join(run_dir, name)
    if not os.path.isfile(path):
        raise RunError(f"{run_dir} has no {name}; a run folder needs {ENV_YAML}, {TRAIN_YAML} and a checkpoint")
    return path


def load_run_configs(run_dir: str) -> tuple[str, Any, Any]:
    """(task, env config, train config) of a run folder, rebuilt from its YAMLs; values outside the rules are
    errors naming the file (they were saved checked, so the file was edited)."""
    from gym_envs.registry import env_cfg_class, train_cfg_class

    train_path = run_file(run_dir, TRAIN_YAML)
    task = run_task(run_dir)
    if not task:
        raise RunError(f"{train_path} names no task")
    env_cfg = load_run_yaml(run_dir, env_cfg_class(task), ENV_YAML)
    train_cfg = load_run_yaml(run_dir, train_cfg_class(task), TRAIN_YAML)
    for name, check in ((ENV_YAML, env_cfg.validate), (TRAIN_YAML, lambda: train_cfg.validate(env_cfg.env.num_envs))):
        try:
            check()
        except ConfigError as err:
            raise ConfigError(f"{os.path.join(run_dir, name)}: {err}") from None
    return task, env_cfg, train_cfg


class DeterministicActor:
    """A trained actor as a callable: observation TensorDict ("actor" group) -> mean action, no grad."""

    def __init__(self, model: torch.nn.Module):
        self.model = model.eval()
        self.device = next(model.parameters()).device

    def __call__(self, obs) -> torch.Tensor:
        with torch.inference_mode():
            return self.model(obs.to(self.device))


@dataclass
class LoadedPolicy:
    run_dir: str
    checkpoint: str
    iteration: int
    task: str
    env_cfg: Any  # as trained (env.yaml); apply evaluation overrides to a copy
    train_cfg: Any
    policy: DeterministicActor


def load_policy(run_dir: str, checkpoint: int = -1, device: str | torch.device = "cpu", env: Any = None,
                cause: str = "") -> LoadedPolicy:
    """A run's configs and its deterministic actor (normaliser included), without building an env.

    The actor's input size comes from the checkpoint; the env built from `env_cfg` gives the same
    size as long as the ORC O-bit and the observation terms are kept. Given the env it will run in
    (a task or TaskVecEnv), a checkpoint whose sizes do not fit it is a RunError naming `cause`.
    """
    from rsl_rl.models import MLPModel
    from tensordict import TensorDict

    from learning.runner_config import to_rsl_rl_dict

    task, env_cfg, train_cfg = load_run_configs(run_dir)
    path = find_checkpoint(run_dir, checkpoint)
    data = load_checkpoint(path, map_location=device)
    if env is not None:
        obs = env.get_observations()
        check_checkpoint_fits(data, path, obs["actor"].shape[1], obs["critic"].shape[1], env.num_actions,
                              f"task {task} as configured", cause)
    in_dim, num_actions = model_io_dims(data["actor_state_dict"])
    rsl = to_rsl_rl_dict(train_cfg)
    # Dummy observations only size the model: all inputs in the first group, the others empty.
    obs = TensorDict({g: torch.zeros(1, in_dim if i == 0 else 0) for i, g in enumerate(rsl["obs_groups"]["actor"])},
                     batch_size=[1])
    actor_cfg = {key: value for key, value in rsl["actor"].items() if key != "class_name"}
    model = MLPModel(obs, rsl["obs_groups"], "actor", num_actions, **actor_cfg).to(device)
    check_layer_shapes(data, path, {"actor_state_dict": model}, f"the actor of {os.path.join(run_dir, TRAIN_YAML)}")
    model.load_state_dict(data["actor_state_dict"])
    return LoadedPolicy(os.path.abspath(run_dir), path, int(data.get("iter", 0)), task, env_cfg, train_cfg,
                        DeterministicActor(model))


def orc_mismatch_cause(trained_env_cfg: Any, env_cfg: Any) -> str:
    """'the ORC O-bit differs (...)' when the phase observations were switched, else ''."""
    before = getattr(getattr(trained_env_cfg, "osc", None), "orc", None)
    now = getattr(getattr(env_cfg, "osc", None), "orc", None)
    if before and now and before[0] != now[0]:
        return f"the ORC O-bit differs (the checkpoint's run used osc.orc={before}, now osc.orc={now})"
    return ""


def plain(value: Any) -> Any:
    """Only types torch.load(weights_only=True) reads back: None, bool, int, float, str, lists, dicts."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    raise TypeError(f"{type(value).__name__} cannot go into a weights_only checkpoint")
