"""Run a trained policy: tracking summary, video, interactive viewer, TorchScript/ONNX export.

    python play.py                                      # newest run under logs/, newest checkpoint
    python play.py --task mini_cheetah_osc --orc 110 --command 1.0 --coupling off --duration 20
    python play.py --load_run 2025-01-01_12-00-00_seed3 --checkpoint 1000 --video walk.mp4 --headless
    python play.py --export                              # <run>/exported/: policy.pt, policy.onnx, controller.onnx
    python play.py --shipped --orc 110                   # the shipped ORC 110 policy, whatever runs exist

Which policy. --load_run (a run folder name or path) and --checkpoint (iteration, -1 newest)
pick it; otherwise the newest run with a checkpoint under the log root, restricted to
--experiment_name, --task and --orc when given. If there is none and --orc is given, the shipped
policy in resources/policies/ORC_<orc>/seed0/ (env.yaml, train.yaml, model_*.pt) is used; --shipped
always plays the shipped one (another shipped seed: --load_run resources/policies/ORC_<orc>/seed<k>).
The first line printed names the checkpoint, its iteration and why it was chosen. --print_config prints
the resolved env config (and the run's train config) as YAML and exits.

What it runs. The env is rebuilt from the run's env.yaml (the task name comes from its
train.yaml) and changed for evaluation:
  * the command is fixed to --command VX [VY YAW] (default 1 0 0) and never resampled; a robot
    that falls is reset with the same command; episodes never time out;
  * observation noise, oscillator process noise and the omega/coupling jitter are 0 (--noise
    keeps the trained values);
  * pushes off (--pushes keeps them); friction/mass/COM randomisation off and resets to the
    default pose at rest (--randomize keeps the trained randomisation and reset ranges);
  * --osc_init sets the initial phases (random, trot, pace, bound, pronk, any_gait, standing);
  * --coupling off sets osc.coupling_max = 0 (the moving coupling; the ORC string is unchanged);
    --orc, given for a run, evaluates the policy under another ORC string (its O bit must match);
  * --set KEY=VALUE changes any other env key (e.g. --set osc.coupling_max=0.5).
Actions are the deterministic policy mean. Every simulated second it prints the mean forward
(body-frame x) velocity over robots, its spread across robots, the yaw rate and the falls.

Output. --video FILE renders robot 0 offscreen with the scene's `track` camera (MuJoCo
backend; MUJOCO_GL defaults to egl when there is no display). Without --headless and with a
display, a passive MuJoCo viewer shows robot 0: arrow keys up/down change v_x by 0.5 m/s,
left/right the yaw rate by 0.5 rad/s, comma/period v_y by 0.25 m/s; it runs until the window
closes unless --duration is given. --export writes the TorchScript and ONNX policy (input: the
actor observation, batch 1 for ONNX; output: actions) to <run>/exported/, or for a shipped
policy to <log_root>/shipped/ORC_<orc>/seed<k>/exported/ (resources/ is never written): both ONNX files
carry deployment metadata (observation terms in order with their scales, action scale, default
joint positions, Kp/Kd, control and physics rates, ORC and oscillator constants), and for
oscillator tasks controller.onnx is the whole controller in one graph (raw readings, per-substep
foot forces, command and phases in; joint targets and new phases out; see learning/export.py).

Every flag and config value is checked before anything is built; a bad one is one line on stderr.
Ctrl-C stops the rollout, prints the summary so far and exits with status 130.
"""

from __future__ import annotations

from learning.startup import quiet_ctrl_c_at_startup

quiet_ctrl_c_at_startup()  # before the slow imports below

import sys  # noqa: E402

from learning.video import VideoRecorder, has_display, prefer_offscreen_gl  # noqa: E402

prefer_offscreen_gl()  # must run before mujoco is imported
_HAS_DISPLAY = has_display()

import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from typing import Any  # noqa: E402

from gym_envs.config import ConfigError  # noqa: E402
from gym_envs.evaluation import evaluation_overrides  # noqa: E402
from gym_envs.oscillators import PHASE_INIT_MODES  # noqa: E402
from learning import cli  # noqa: E402

DEFAULT_DURATION_S = 10.0
KEY_UP, KEY_DOWN, KEY_LEFT, KEY_RIGHT, KEY_COMMA, KEY_PERIOD = 265, 264, 263, 262, 44, 46


def build_parser() -> cli.Parser:
    p = cli.Parser("play.py", __doc__)
    p.add_argument("--task", help="task name; optional when a run is found (read from its train.yaml)")
    p.add_argument("--orc", type=cli.orc, help="pick the newest run with this ORC string (or the shipped ORC_<orc> "
                   "policy)")
    p.add_argument("--shipped", action="store_true", help="play the shipped policy resources/policies/ORC_<orc>/seed0 "
                   "(--orc, default 111) even when runs exist")
    cli.add_run_selection(p, "play")
    p.add_argument("--num_envs", type=cli.integer(1), default=50, help="robots (default 50)")
    p.add_argument("--duration", type=cli.number(0.0, low_open=True),
                   help=f"simulated seconds (default {DEFAULT_DURATION_S:g}; in the viewer, until the window closes)")
    p.add_argument("--command", type=cli.number(), nargs="+", metavar="V", default=[1.0, 0.0, 0.0],
                   help="VX [VY YAW]: fixed body-frame command (default 1 0 0)")
    p.add_argument("--osc_init", choices=PHASE_INIT_MODES,
                   help="initial oscillator phases (default: the run's, i.e. random)")
    p.add_argument("--coupling", choices=("on", "off"), help="off: osc.coupling_max=0 (default: as trained)")
    p.add_argument("--noise", action="store_true", help="keep observation/oscillator noise and jitter")
    p.add_argument("--pushes", action="store_true", help="keep random pushes")
    p.add_argument("--randomize", action="store_true", help="keep domain randomisation and randomised resets")
    p.add_argument("--seed", type=cli.integer(0), help="env.seed (default: the run's)")
    cli.add_overrides(p, "env config override, repeatable (e.g. osc.coupling_max=0.5)")
    cli.add_compute(p, device_default="cpu")
    p.add_argument("--headless", action="store_true", help="never open a viewer window")
    p.add_argument("--video", metavar="FILE.mp4", type=cli.new_file(".mp4"), help="render robot 0 to this video")
    p.add_argument("--export", action="store_true", help="write exported/policy.pt, policy.onnx and controller.onnx "
                   "(with metadata; in the run folder, for a shipped policy in <log_root>/shipped/ORC_<orc>/seed<k>/)")
    cli.add_print_config(p)
    return p


def locate_run(args, log_root: str) -> tuple[str, str]:
    """(run folder, why it was chosen)."""
    from learning import runs

    if args.shipped:
        if args.load_run:
            raise ConfigError("--shipped and --load_run both choose the policy; pass one of them")
        orc = args.orc or "111"
        shipped = runs.shipped_policy_dir(orc)
        if not (runs.is_run_dir(shipped) and runs.list_checkpoints(shipped)):
            raise runs.RunError(f"no shipped policy at {shipped}")
        return shipped, f"the shipped ORC {orc} policy"
    if args.load_run:
        return runs.find_run(log_root, args.load_run, experiment=args.experiment_name), "--load_run"
    try:
        run_dir = runs.find_run(log_root, None, experiment=args.experiment_name, task=args.task, orc=args.orc)
    except runs.RunError as err:
        if not args.orc or "cannot be read" in str(err):
            raise
        shipped = runs.shipped_policy_dir(args.orc)
        if runs.is_run_dir(shipped) and runs.list_checkpoints(shipped):
            return shipped, f"the shipped ORC {args.orc} policy (no run of it under {log_root})"
        raise runs.RunError(
            f"{err}; no shipped policy at {shipped} either (train one: python train.py --task "
            f"{args.task or 'mini_cheetah_osc'} --orc {args.orc})"
        ) from None
    filters = " ".join(f for f in (f"task {args.task}" if args.task else "",
                                    f"ORC {args.orc}" if args.orc else "") if f)
    return run_dir, f"the newest run{' of ' + filters if filters else ''} under {log_root}"


def play_overrides(env_cfg, args) -> list[str]:
    """The env overrides that turn the run's training env into the evaluation env."""
    if len(args.command) not in (1, 3):
        raise ConfigError(f"--command takes VX or VX VY YAW, got {len(args.command)} numbers")
    vx, vy, yaw = (list(args.command) + [0.0, 0.0])[:3]
    has_osc = hasattr(env_cfg, "osc")
    items = [f"env.num_envs={args.num_envs}"] + evaluation_overrides(
        env_cfg, (vx, vy, yaw), observation_noise=args.noise, oscillator_noise=args.noise,
        pushes=args.pushes, randomize=args.randomize,
    )
    if (args.osc_init or args.coupling or args.orc) and not has_osc:
        raise ConfigError("--osc_init, --coupling and --orc need a task with oscillators")
    if args.coupling == "off":
        items.append("osc.coupling_max=0.0")
    # On the CPU the threaded mujoco.batch backend, also for a run trained with Warp on a GPU: Warp's CPU device
    # compiles its kernels first and steps slower, and a laptop may not have the gpu extra at all.
    sim = args.sim or ("mujoco" if args.device == "cpu" else None)
    given = {"osc.init": args.osc_init, "osc.orc": args.orc, "env.seed": args.seed, "sim.backend": sim,
             "sim.num_threads": args.num_threads, "env.device": args.device}
    return items + [f"{key}={value}" for key, value in given.items() if value is not None]


@dataclass
class Choice:
    """The policy play.py will run and its evaluation configs, checked; nothing built yet."""

    run_dir: str
    chosen_as: str  # why this run: shown to the user
    checkpoint: str
    iteration: int
    task_name: str
    trained_env_cfg: Any  # as in the run's env.yaml
    env_cfg: Any  # the evaluation env config
    train_cfg: Any
    log_root: str

    @property
    def orc(self) -> str | None:
        return getattr(getattr(self.env_cfg, "osc", None), "orc", None)


def choose(args) -> Choice:
    import torch

    from gym_envs.config import apply_overrides
    from learning import runs

    if any(item.strip().startswith("train.") for item in args.overrides):
        raise ConfigError("play.py takes env overrides only; train.* keys have no effect here")
    if args.device == "cuda" and not torch.cuda.is_available():
        raise ConfigError("--device cuda, but torch sees no CUDA device")
    log_root = args.log_root or runs.default_log_root()
    run_dir, chosen_as = locate_run(args, log_root)
    checkpoint = runs.find_checkpoint(run_dir, args.checkpoint)
    task, trained_env, train_cfg = runs.load_run_configs(run_dir)
    if args.task and args.task != task:
        raise ConfigError(f"run {run_dir} trained task {task!r}, not {args.task!r}")
    env_cfg = apply_overrides(trained_env, play_overrides(trained_env, args) + list(args.overrides))
    env_cfg.validate()
    return Choice(run_dir, chosen_as, checkpoint, runs.checkpoint_iteration(checkpoint), task, trained_env, env_cfg,
                  train_cfg, log_root)


class Session:
    """The loaded policy and its evaluation env."""

    def __init__(self, args, choice: Choice | None = None):
        from gym_envs import make_env
        from gym_envs.orc import parse_orc
        from learning import runs
        from learning.vec_env import TaskVecEnv

        self.choice = choice = choice or choose(args)
        self.run_dir, self.checkpoint, self.task_name, self.orc = (choice.run_dir, choice.checkpoint,
                                                                   choice.task_name, choice.orc)
        if self.orc is not None and args.coupling == "on" and not parse_orc(self.orc).coupling:
            print(f"note: ORC {self.orc} has C=0, so the coupling stays 0; pass --orc with C=1 to couple")
        self.env = TaskVecEnv(make_env(choice.task_name, choice.env_cfg), device=args.device)
        self.policy = runs.load_policy(choice.run_dir, choice.iteration, args.device, env=self.env,
                                       cause=runs.orc_mismatch_cause(choice.trained_env_cfg, choice.env_cfg)).policy

    @property
    def task(self):
        return self.env.task

    def set_command(self, vx: float, vy: float, yaw: float) -> None:
        """Change the fixed command of every robot (also what a reset draws)."""
        c = self.task.cfg.commands
        c.lin_vel_x, c.lin_vel_y, c.yaw_rate = (vx, vx), (vy, vy), (yaw, yaw)
        self.task.commands[:] = self.task.commands.new_tensor([vx, vy, yaw])


class Tracker:
    """Per-second tracking summary over all robots."""

    def __init__(self, dt: float, num_envs: int):
        import torch

        self.steps_per_window = max(1, round(1.0 / dt))
        self.dt = dt
        self.vx = torch.zeros(num_envs)
        self.yaw = torch.zeros(num_envs)
        self.n = 0
        self.falls = 0
        self.total_falls = 0
        self.time = 0.0
        self.history: list[float] = []
        print(f"{'t [s]':>7} {'cmd vx':>7} {'vx mean':>8} {'vx std':>7} {'yaw rate':>9} {'falls':>6} {'total':>6}")

    def record(self, task) -> None:
        self.vx += task.base_lin_vel[:, 0].detach().cpu()
        self.yaw += task.base_ang_vel[:, 2].detach().cpu()
        fell = int(task.terminated.sum())
        self.falls += fell
        self.total_falls += fell
        self.n += 1
        self.time += self.dt
        if self.n == self.steps_per_window:
            self.flush(task)

    def flush(self, task) -> None:
        if self.n == 0:
            return
        vx, yaw = self.vx / self.n, self.yaw / self.n
        cmd = float(task.commands[:, 0].mean())
        self.history.append(float(vx.mean()))
        print(f"{self.time:7.2f} {cmd:7.2f} {float(vx.mean()):8.3f} {float(vx.std(unbiased=False)):7.3f} "
              f"{float(yaw.mean()):9.3f} {self.falls:6d} {self.total_falls:6d}", flush=True)
        self.vx.zero_()
        self.yaw.zero_()
        self.n = self.falls = 0


class Viewer:
    """Passive MuJoCo viewer of robot 0; arrow keys change the command."""

    def __init__(self, session: Session, command: list[float]):
        import mujoco
        import mujoco.viewer

        self.mujoco, self.session = mujoco, session
        self.sim = session.task.sim
        self.model = self.sim.model
        self.data = mujoco.MjData(self.model)
        self.command = list(command)
        self.pending = None
        self.handle = mujoco.viewer.launch_passive(self.model, self.data, key_callback=self._key)
        print("viewer: up/down v_x +-0.5, left/right yaw rate +-0.5, comma/period v_y +-0.25; close the window to stop")

    def _key(self, keycode: int) -> None:
        steps = {KEY_UP: (0, 0.5), KEY_DOWN: (0, -0.5), KEY_LEFT: (2, 0.5), KEY_RIGHT: (2, -0.5),
                 KEY_COMMA: (1, 0.25), KEY_PERIOD: (1, -0.25)}
        if keycode in steps:
            axis, delta = steps[keycode]
            self.command[axis] = round(self.command[axis] + delta, 3)
            self.pending = tuple(self.command)

    def running(self) -> bool:
        return self.handle.is_running()

    def update(self) -> None:
        if self.pending is not None:
            command, self.pending = self.pending, None
            self.session.set_command(*command)
            print(f"command: v_x {command[0]:+.2f}  v_y {command[1]:+.2f}  yaw {command[2]:+.2f}", flush=True)
        self.sim.copy_state_to(0, self.data)
        self.mujoco.mj_forward(self.model, self.data)
        self.handle.sync()

    def close(self) -> None:
        self.handle.close()


def main(argv: list[str] | None = None) -> int:
    return cli.run(build_parser(), _main, argv)


def _main(args) -> int:
    import torch

    from learning import runs

    threads_before = torch.get_num_threads()
    video = viewer = None
    try:
        if args.num_threads:
            torch.set_num_threads(args.num_threads)
        choice = choose(args)
        if args.print_config:
            print(cli.config_yaml(choice.env_cfg, choice.train_cfg), end="")
            return 0
        session = Session(args, choice)
        if args.video:
            video = VideoRecorder(session.task.sim, session.env.dt, args.video)
        print(f"policy {choice.checkpoint} (iteration {choice.iteration}; {choice.chosen_as}) | task "
              f"{choice.task_name}" + (f" (ORC {choice.orc})" if choice.orc else "")
              + f" | {session.env.num_envs} robots")
        if not runs.is_shipped(choice.run_dir):
            print("other policies: --load_run RUN --checkpoint N; the shipped one: --shipped --orc "
                  f"{choice.orc or '111'}")
        if args.export:
            from learning.export import export_deployment

            paths = export_deployment(session.policy.model, session.task,
                                      runs.export_dir(choice.run_dir, choice.log_root), choice.checkpoint)
            print(f"exported {', '.join(paths)}")

        interactive = not args.headless and _HAS_DISPLAY and video is None
        if interactive:
            viewer = Viewer(session, (list(args.command) + [0.0, 0.0])[:3])
        elif not args.headless and not _HAS_DISPLAY and video is None:
            print("no display: running without a viewer")
        duration = args.duration if args.duration is not None else (None if interactive else DEFAULT_DURATION_S)
        dt = session.env.dt
        steps = None if duration is None else max(1, round(duration / dt))
        tracker = Tracker(dt, session.env.num_envs)
        obs = session.env.get_observations()
        step = 0
        interrupted = False
        wall_start = time.perf_counter()
        try:
            while steps is None or step < steps:
                if viewer is not None and not viewer.running():
                    break
                with torch.inference_mode():
                    obs, _, _, _ = session.env.step(session.policy(obs))
                tracker.record(session.task)
                if video is not None:
                    video.capture(step)
                if viewer is not None:
                    viewer.update()
                    lag = wall_start + (step + 1) * dt - time.perf_counter()
                    if lag > 0:
                        time.sleep(lag)
                step += 1
        except KeyboardInterrupt:  # the summary of what ran is still printed; the status says it was cut short
            interrupted = True
            print("interrupted")
        tracker.flush(session.task)
        if tracker.history:
            print(f"mean forward velocity {sum(tracker.history) / len(tracker.history):.3f} m/s over "
                  f"{step * dt:.2f} s; {tracker.total_falls} falls")
        if video is not None:
            print(f"video {args.video}: {video.frames} frames")
        return cli.EXIT_INTERRUPTED if interrupted else 0
    finally:
        if video is not None:
            video.close()
        if viewer is not None:
            viewer.close()
        torch.set_num_threads(threads_before)


if __name__ == "__main__":
    sys.exit(main())
