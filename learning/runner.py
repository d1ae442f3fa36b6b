"""OnPolicyRunner with orcgym's run conventions.

Differences from rsl-rl-lib's runner (its PPO, models, storage and tensorboard logging are used
as they are):
  * iterations are counted as *completed* iterations: `model_<n>.pt` holds the networks after n
    PPO updates and records iter=n, and resuming from it runs iteration index n next (rsl-rl's own
    loop would repeat index n-1);
  * checkpoints are written atomically and loaded with weights_only=True, after checking that
    their network sizes fit the task;
  * a stop request (Ctrl-C, see `StopRequest`) ends training at the next env step: the partial
    rollout is dropped and the last completed iteration is saved;
  * one compact progress line per iteration instead of rsl-rl's block; `Perf/env_steps_per_s`
    (rollout throughput) is logged to tensorboard beside rsl-rl's `Perf/total_fps`;
  * under torchrun the process group's backend follows the device (gloo on CPU, NCCL on CUDA; see
    learning.distributed) instead of rsl-rl's NCCL-only `cuda:<local_rank>` set-up.
"""

from __future__ import annotations

import contextlib
import datetime
import io
import pathlib
import signal
import statistics
import time

import torch
from rsl_rl.runners import OnPolicyRunner
from rsl_rl.utils import check_nan
from rsl_rl.utils.log_writer import LogWriter
from rsl_rl.utils.logger import Logger

from learning import distributed, runs
from learning.runner_config import TrainCfg, to_rsl_rl_dict
from learning.vec_env import TaskVecEnv


@contextlib.contextmanager
def quiet():
    """Silence rsl-rl's prints (model summaries, observation-set tables, per-iteration blocks)."""
    with contextlib.redirect_stdout(io.StringIO()):
        yield


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
    """rsl-rl's tensorboard logging with a one-line console summary per iteration."""

    prefix = ""
    # Means over the episodes that ended in the last logged iteration (None before any ended).
    last_reward: float | None = None
    last_tracking_error: float | None = None

    def log(self, it, start_it, total_it, collect_time, learn_time, loss_dict, learning_rate, action_std,
            rnd_weight, print_minimal=False, width=80, pad=40) -> None:
        if self.writer is None:
            return
        errors = [float(e["Episode/tracking_error"]) for e in self.ep_extras if "Episode/tracking_error" in e]
        if errors:
            self.last_tracking_error = statistics.mean(errors)
        if self.rewbuffer:
            self.last_reward = statistics.mean(self.rewbuffer)
        with quiet():
            super().log(it, start_it, total_it, collect_time, learn_time, loss_dict, learning_rate, action_std,
                        rnd_weight, print_minimal, width, pad)
        steps = self.cfg["num_steps_per_env"] * self.num_envs * self.gpu_world_size
        env_sps = steps / max(collect_time, 1e-9)
        self.writer.add_scalar("Perf/env_steps_per_s", env_sps, it)
        done = it + 1 - start_it
        eta = self.tot_time / done * (total_it - it - 1)
        reward = f"{statistics.mean(self.rewbuffer):8.3f}" if self.rewbuffer else "       -"
        ep_len = f"{statistics.mean(self.lenbuffer):6.1f}" if self.lenbuffer else "     -"
        print(
            f"{self.prefix}it {it + 1:>{len(str(total_it))}}/{total_it} | "
            f"{steps / (collect_time + learn_time):9,.0f} steps/s (env {env_sps:,.0f}) | "
            f"reward {reward} | ep len {ep_len} | value loss {loss_dict['value']:.4f} | lr {learning_rate:.1e} | "
            f"ETA {datetime.timedelta(seconds=int(eta))}",
            flush=True,
        )


    def save_video(self, path: str, it: int) -> None:
        """Upload a clip finished after the last `log` (rsl-rl's `log` uploads the others; W&B only)."""
        if isinstance(self.writer, LogWriter):
            self.writer.save_video(pathlib.Path(path), it)


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
        """Where checkpoints and tensorboard events go (set before `train`)."""
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

    def learn(self, num_learning_iterations: int, init_at_random_ep_len: bool = False) -> None:
        self.train(self.current_learning_iteration + num_learning_iterations, init_at_random_ep_len)

    def train(self, until: int, init_at_random_ep_len: bool = True, stop: StopRequest | None = None) -> bool:
        """Run PPO iterations until `until` have completed; False if a stop request cut it short.

        Checkpoints: model_0 before a fresh start, every save_interval completed iterations, at the
        end, and at a stop.
        """
        stop = stop or StopRequest()
        env, alg, cfg = self.env, self.alg, self.cfg
        if init_at_random_ep_len:
            env.episode_length_buf = torch.randint_like(env.episode_length_buf, high=int(env.max_episode_length))
        obs = env.get_observations().to(self.device)
        alg.train_mode()
        if self.is_distributed:
            alg.broadcast_parameters()
        distributed.log_sync_digest([alg.actor, alg.critic], self.current_learning_iteration, self.gpu_global_rank)
        with quiet():
            self.logger.init_logging_writer()
        start = self.current_learning_iteration
        if start == 0:
            self._save_iteration()
        finished = True
        try:
            for it in range(start, until):
                t0 = time.perf_counter()
                if self.video is not None:
                    self.video.start_iteration(it)
                with torch.inference_mode():
                    for _ in range(cfg["num_steps_per_env"]):
                        if stop.requested and not self.is_distributed:
                            break
                        actions = alg.act(obs)
                        obs, rewards, dones, extras = env.step(actions.to(env.device))
                        if self.video is not None:
                            self.video.after_step()
                        if cfg.get("check_for_nan", True):
                            check_nan(obs, rewards, dones)
                        obs, rewards, dones = obs.to(self.device), rewards.to(self.device), dones.to(self.device)
                        alg.process_env_step(obs, rewards, dones, extras)
                        self.logger.process_env_step(rewards, dones, extras, None)
                    if self._stop_everywhere(stop):
                        alg.storage.clear()  # drop the partial rollout; the networks are those of `it`
                        finished = False
                        break
                    t1 = time.perf_counter()
                    alg.compute_returns(obs)
                losses = alg.update()
                t2 = time.perf_counter()
                self.current_learning_iteration = it + 1
                distributed.log_sync_digest([alg.actor, alg.critic], it + 1, self.gpu_global_rank)
                self.logger.log(
                    it=it, start_it=start, total_it=until, collect_time=t1 - t0, learn_time=t2 - t1,
                    loss_dict=losses, learning_rate=alg.learning_rate, action_std=alg.get_policy().output_std,
                    rnd_weight=None,
                )
                if (it + 1) % cfg["save_interval"] == 0 and it + 1 != until:
                    self._save_iteration()
            self._save_iteration()
        finally:
            last_clip = self.video.close() if self.video is not None else None
            if last_clip is not None:
                self.logger.save_video(last_clip, self.current_learning_iteration)
            if self.logger.writer is not None:
                self.logger.writer.flush()
                self.logger.writer.close()
                self.logger.stop_logging_writer()  # W&B / Neptune: finish the remote run
        return finished

    def _stop_everywhere(self, stop: StopRequest) -> bool:
        if not self.is_distributed:
            return stop.requested
        flag = torch.tensor(float(stop.requested), device=self.device)
        torch.distributed.all_reduce(flag, op=torch.distributed.ReduceOp.MAX)
        return bool(flag.item())

    def _save_iteration(self) -> None:
        if self.writes_files:
            self.save(runs.checkpoint_path(self.log_dir, self.current_learning_iteration))

    # --- checkpoints ---------------------------------------------------------------------------

    def save(self, path: str, infos: dict | None = None) -> None:
        data = self.alg.save()
        data["iter"] = int(self.current_learning_iteration)
        data["infos"] = runs.plain(infos)
        runs.save_checkpoint(data, path)
        self.logger.save_model(path, self.current_learning_iteration)

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
