"""rsl-rl-lib's OnPolicyRunner and its training loop (`learn`), with orcgym's run conventions hung on its hooks.

What differs from rsl-rl-lib's runner (its loop, PPO, models, storage and tensorboard logging are used as
they are):
  * iterations are counted as *completed* iterations: `model_<n>.pt` holds the networks after n
    PPO updates and records iter=n, and resuming from it runs iteration index n next;
  * checkpoints are written atomically and loaded with weights_only=True, after checking that
    their network sizes fit the task;
  * a stop request (Ctrl-C or SIGTERM, see `StopRequest`) ends training at the next env step: the
    partial rollout is dropped and the last completed iteration is saved;
  * one compact progress line per iteration instead of rsl-rl's block; `Perf/env_steps_per_s`
    (rollout throughput) is logged to tensorboard beside rsl-rl's `Perf/total_fps`; clips of robot 0
    while training (learning.video);
  * under torchrun the process group's backend follows the device (gloo on CPU, NCCL on CUDA; see
    learning.distributed) instead of rsl-rl's NCCL-only `cuda:<local_rank>` set-up.
The per-step and per-iteration work runs in rsl-rl's logger callbacks (`ProgressLogger`), which its loop
calls after every env step and every update.
"""

from __future__ import annotations

import contextlib
import datetime
import io
import pathlib
import signal
import statistics

import torch
from rsl_rl.modules import EmpiricalNormalization
from rsl_rl.runners import OnPolicyRunner
from rsl_rl.utils.log_writer import LogWriter
from rsl_rl.utils.logger import Logger

from learning import distributed, runs
from gym_envs.train_config import TrainCfg
from learning.runner_config import to_rsl_rl_dict
from learning.vec_env import TaskVecEnv


def quiet() -> contextlib.redirect_stdout:
    """Silence rsl-rl's prints (model summaries, observation-set tables, per-iteration blocks)."""
    return contextlib.redirect_stdout(io.StringIO())


class StopRequest:
    """Turns SIGINT (Ctrl-C) and SIGTERM (what SLURM and Kubernetes send before SIGKILL) into a request
    that training honours at the next env step; a second signal aborts without saving.

    Under torchrun the launcher passes either signal on to every rank; only the one with `announce`
    says so, and the ranks agree on the iteration they stop at (TaskRunner._stop_everywhere).
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self, announce: bool = True) -> None:
        self.requested = False
        self.announce = announce
        self.signum = signal.SIGINT
        self._previous: dict = {}

    @property
    def exit_status(self) -> int:
        """128 + the signal's number, as a shell reports a process that signal ended: 130 or 143."""
        return 128 + int(self.signum)

    def _handle(self, signum, frame) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested, self.signum = True, signum
        if self.announce:
            name = "Ctrl-C" if signum == signal.SIGINT else signal.Signals(signum).name
            print(f"\n{name}: stopping after this step; saving a checkpoint (again to abort without saving)",
                  flush=True)

    def __enter__(self) -> StopRequest:
        for signum in self.SIGNALS:
            try:
                self._previous[signum] = signal.signal(signum, self._handle)
            except ValueError:  # not the main thread: no handler, the signal keeps its default
                pass
        return self

    def __exit__(self, *exc) -> None:
        for signum, previous in self._previous.items():
            signal.signal(signum, previous)
        self._previous = {}


class ProgressLogger(Logger):
    """rsl-rl's tensorboard logging with a one-line console summary per iteration, and the runner's hooks.

    rsl-rl's loop calls `process_env_step` after every env step and `log` after every update; TaskRunner
    hangs its per-step and per-iteration work (video, stop requests) there through `after_step` and
    `after_iteration`, so that the loop itself stays rsl-rl's.
    """

    prefix = ""
    # Means over the episodes that ended in the last logged iteration (None before any ended).
    last_reward: float | None = None
    last_tracking_error: float | None = None
    on_start = after_step = after_iteration = before_stop = staticmethod(lambda *args: None)

    def init_logging_writer(self) -> None:
        with quiet():
            super().init_logging_writer()
        self.on_start()

    def process_env_step(self, *args, **kwargs) -> None:
        super().process_env_step(*args, **kwargs)
        self.after_step()

    def log(self, **kwargs) -> None:
        # rsl-rl's `it` is the completed count here (see TaskRunner.learn); its events keep the index of the
        # iteration (0 for the first), as they always had.
        completed = kwargs["it"]
        if self.writer is not None:
            self._record(completed, kwargs)
        self.after_iteration(completed)

    def _record(self, completed: int, kwargs: dict) -> None:
        it, start, total = completed - 1, kwargs["start_it"] - 1, kwargs["total_it"] - 1
        errors = [float(e["Episode/tracking_error"]) for e in self.ep_extras if "Episode/tracking_error" in e]
        if errors:
            self.last_tracking_error = statistics.mean(errors)
        if self.rewbuffer:
            self.last_reward = statistics.mean(self.rewbuffer)
        with quiet():
            super().log(**{**kwargs, "it": it, "start_it": start, "total_it": total})
        collect_time, learn_time = kwargs["collect_time"], kwargs["learn_time"]
        steps = self.cfg["num_steps_per_env"] * self.num_envs * self.gpu_world_size
        env_sps = steps / max(collect_time, 1e-9)
        self.writer.add_scalar("Perf/env_steps_per_s", env_sps, it)
        eta = self.tot_time / (completed - start) * (total - completed)
        reward = f"{statistics.mean(self.rewbuffer):8.3f}" if self.rewbuffer else "       -"
        ep_len = f"{statistics.mean(self.lenbuffer):6.1f}" if self.lenbuffer else "     -"
        print(
            f"{self.prefix}it {completed:>{len(str(total))}}/{total} | "
            f"{steps / (collect_time + learn_time):9,.0f} steps/s (env {env_sps:,.0f}) | "
            f"reward {reward} | ep len {ep_len} | value loss {kwargs['loss_dict']['value']:.4f} | "
            f"lr {kwargs['learning_rate']:.1e} | ETA {datetime.timedelta(seconds=int(eta))}",
            flush=True,
        )

    def stop_logging_writer(self) -> None:
        """Flush and close the writer (rsl-rl leaves tensorboard's open); called at the end and at a stop."""
        self.before_stop()
        if self.writer is not None:
            self.writer.flush()
            self.writer.close()
            super().stop_logging_writer()  # W&B / Neptune: finish the remote run
            self.writer = None

    def save_video(self, path: str, it: int) -> None:
        """Upload a clip finished after the last `log` (rsl-rl's `log` uploads the others; W&B only)."""
        if isinstance(self.writer, LogWriter):
            self.writer.save_video(pathlib.Path(path), it)


class _Stopped(Exception):
    """Leaves rsl-rl's loop when a stop was requested."""


class TaskRunner(OnPolicyRunner):
    """An OnPolicyRunner for a gym_envs task; `train_cfg` is a typed TrainCfg."""

    def __init__(self, env: TaskVecEnv, train_cfg: TrainCfg, log_dir: str | None = None, device: str = "cpu"):
        self.train_cfg = train_cfg
        if train_cfg.algorithm.symmetry_cfg.enabled:
            env.mirror_maps  # noqa: B018  (builds the maps now: an asymmetric model fails before any file is written)
        with quiet():
            super().__init__(env, to_rsl_rl_dict(train_cfg), log_dir=log_dir, device=device)
        self.logger = ProgressLogger(
            log_dir=log_dir, cfg=self.cfg, env_cfg=env.cfg, num_envs=env.num_envs, is_distributed=self.is_distributed,
            gpu_world_size=self.gpu_world_size, gpu_global_rank=self.gpu_global_rank, device=self.device,
        )
        self.logger.git_status_repos = [runs.REPO_ROOT]
        self.logger.on_start, self.logger.after_step = self._on_start, self._after_step
        self.logger.after_iteration, self.logger.before_stop = self._after_iteration, self._close_video
        self._stop, self._completed, self._last_saved = StopRequest(), 0, None
        self.log_dir = log_dir
        self.video = None  # a learning.video.TrainingVideo records clips of robot 0 while training when set

    def _configure_multi_gpu(self) -> None:
        # rsl-rl's names; "gpu" here means any process of a torchrun launch, CPU or GPU.
        ranks = distributed.ranks_from_env()
        self.is_distributed = ranks.is_distributed
        self.gpu_world_size, self.gpu_global_rank, self.gpu_local_rank = ranks.world_size, ranks.rank, ranks.local_rank
        self.cfg["multi_gpu"] = None
        if self.is_distributed:
            distributed.init_process_group(str(self.device), ranks)
            self.cfg["multi_gpu"] = {"global_rank": ranks.rank, "local_rank": ranks.local_rank,
                                     "world_size": ranks.world_size}

    def attach_run_dir(self, run_dir: str, progress_prefix: str = "") -> None:
        """Where checkpoints and tensorboard events go (set before `learn`)."""
        self.log_dir = self.logger.log_dir = run_dir
        self.logger.prefix = progress_prefix
        if self.video is not None:
            self.video.write_into(run_dir)

    # --- sizes ---------------------------------------------------------------------------------

    @property
    def obs_dims(self) -> tuple[int, int]:
        return self.alg.actor.obs_dim, self.alg.critic.obs_dim

    def describe(self) -> str:
        a, c = self.obs_dims
        hid_a = list(self.train_cfg.actor.hidden_dims)
        hid_c = list(self.train_cfg.critic.hidden_dims)
        return f"actor {a} -> {hid_a} -> {self.env.num_actions}, critic {c} -> {hid_c} -> 1"

    @property
    def writes_files(self) -> bool:
        return self.log_dir is not None and not self.logger.disable_logs

    # --- training ------------------------------------------------------------------------------

    def learn(self, num_learning_iterations: int, init_at_random_ep_len: bool = True,
              stop: StopRequest | None = None) -> bool:
        """rsl-rl's `learn` for `num_learning_iterations` more iterations; False if `stop` cut it short.

        Checkpoints: model_0 before a fresh start, every save_interval completed iterations, at the end
        and at a stop. A stop ends the run at the next env step (the partial rollout is dropped); under
        torchrun after the current update, at the same iteration on every rank.
        """
        self._stop = stop or StopRequest()
        self._completed = start = self.current_learning_iteration
        if start == 0:
            self._save_iteration()
        if self.video is not None:
            self.video.start_iteration(start)
        # rsl-rl names an iteration by its loop index and saves at index % save_interval == 0. Started one past
        # the completed count, the index of an iteration whose update is done is the completed count, which is
        # what checkpoint names here count.
        self.current_learning_iteration = start + 1
        try:
            super().learn(num_learning_iterations, init_at_random_ep_len)
            return True
        except _Stopped:
            self.alg.storage.clear()  # the networks are those of the last completed iteration
            self.current_learning_iteration = self._completed
            self._save_iteration()
            return False
        finally:
            self.logger.stop_logging_writer()

    def _on_start(self) -> None:
        self._freeze_normalisers_when_due(self._completed)
        distributed.log_sync_digest([self.alg.actor, self.alg.critic], self._completed, self.gpu_global_rank)

    def _after_step(self) -> None:
        if self.video is not None:
            self.video.after_step()
        if self._stop.requested and not self.is_distributed:
            raise _Stopped

    def _after_iteration(self, completed: int) -> None:
        self._completed = completed
        self._freeze_normalisers_when_due(completed)
        distributed.log_sync_digest([self.alg.actor, self.alg.critic], completed, self.gpu_global_rank)
        if self._stop_everywhere():
            raise _Stopped
        if self.video is not None:
            self.video.start_iteration(completed)

    def _freeze_normalisers_when_due(self, completed: int) -> None:
        frozen_from = self.train_cfg.obs_normalization_frozen_from
        if not frozen_from or completed < frozen_from:
            return
        for model in (self.alg.actor, self.alg.critic):
            if isinstance(model.obs_normalizer, EmpiricalNormalization):
                model.obs_normalizer.until = 0  # rsl-rl's normaliser stops learning once its count reaches `until`

    def _stop_everywhere(self) -> bool:
        if not self.is_distributed:
            return self._stop.requested
        flag = torch.tensor(float(self._stop.requested), device=self.device)
        torch.distributed.all_reduce(flag, op=torch.distributed.ReduceOp.MAX)
        return bool(flag.item())

    def _close_video(self) -> None:
        last_clip = self.video.close() if self.video is not None else None
        if last_clip is not None:
            self.logger.save_video(last_clip, self.current_learning_iteration)

    def _save_iteration(self) -> None:
        if self.writes_files:
            self.save(runs.checkpoint_path(self.log_dir, self.current_learning_iteration))

    # --- checkpoints ---------------------------------------------------------------------------

    def save(self, path: str, infos: dict | None = None) -> None:
        """Atomic; rsl-rl's loop saves the final iteration twice when it falls on save_interval: once is enough."""
        if self._last_saved == (path, self.current_learning_iteration):
            return
        data = self.alg.save()
        data["iter"] = int(self.current_learning_iteration)
        data["infos"] = runs.plain(infos)
        runs.save_checkpoint(data, path)
        self.logger.save_model(path, self.current_learning_iteration)
        self._last_saved = (path, self.current_learning_iteration)

    def load(self, path: str, load_cfg: dict | None = None, strict: bool = True, map_location=None,
             context: str = "this task", cause: str = "") -> dict | None:
        """Load a checkpoint (weights_only) after checking that its network sizes fit this task."""
        data = runs.load_checkpoint(path, map_location=map_location or self.device)
        runs.check_checkpoint_fits(data, path, *self.obs_dims, self.env.num_actions, context, cause)
        runs.check_layer_shapes(data, path, {"actor_state_dict": self.alg.actor, "critic_state_dict": self.alg.critic},
                                context)
        if self.alg.load(data, load_cfg, strict):
            self.current_learning_iteration = int(data.get("iter", 0))
        return data.get("infos")

    def set_learning_rate(self, rate: float) -> None:
        """The PPO learning rate from now on (the adaptive schedule, if on, starts from it)."""
        self.alg.learning_rate = rate
        for group in self.alg.optimizer.param_groups:
            group["lr"] = rate
