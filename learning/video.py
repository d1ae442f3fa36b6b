"""Offscreen video of robot 0: play.py's --video FILE and train.py's --video N (a clip every N iterations).

Rendering uses MuJoCo's own `Renderer` with the scene's `track` camera, on the MuJoCo backends
(both keep an `MjModel` and can copy one env's state into an `MjData`). Without a display, MuJoCo
must be told to render through EGL before it is imported (`prefer_offscreen_gl`); MUJOCO_GL=osmesa
is the software fallback where EGL is missing.
"""

from __future__ import annotations

import os
import shutil
import tempfile

from gym_envs.config import ConfigError

VIDEO_FPS = 50
VIDEO_SIZE = (480, 640)  # height, width
VIDEO_DIR = "videos"


def has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def prefer_offscreen_gl() -> None:
    """Without a display, render through EGL unless MUJOCO_GL says otherwise; call before importing mujoco."""
    if not has_display() and not os.environ.get("MUJOCO_GL"):  # set but empty counts as unset
        os.environ["MUJOCO_GL"] = "egl"


class VideoRecorder:
    """Frames of env 0 at about VIDEO_FPS into an mp4 file."""

    def __init__(self, sim, dt: float, path: str):
        import imageio
        import mujoco

        self.mujoco = mujoco
        self.sim = sim
        self.model = getattr(sim, "model", None)
        if self.model is None or not hasattr(sim, "copy_state_to"):
            raise ConfigError(f"video needs a MuJoCo backend with a model to render; {type(sim).__name__} has none")
        self.data = mujoco.MjData(self.model)
        height = min(VIDEO_SIZE[0], self.model.vis.global_.offheight)
        width = min(VIDEO_SIZE[1], self.model.vis.global_.offwidth)
        try:
            self.renderer = mujoco.Renderer(self.model, height, width)
        except Exception as err:  # no usable OpenGL platform
            gl = os.environ.get("MUJOCO_GL", "(unset)")
            raise ConfigError(f"offscreen rendering failed with MUJOCO_GL={gl} ({' '.join(str(err).split())}); "
                              f"try MUJOCO_GL=egl or MUJOCO_GL=osmesa") from None
        self.every = max(1, round(1.0 / (dt * VIDEO_FPS)))
        self.path = path
        self.writer = imageio.get_writer(path, fps=1.0 / (dt * self.every), macro_block_size=8)
        self.frames = 0

    def capture(self, step: int) -> None:
        if step % self.every:
            return
        self.sim.copy_state_to(0, self.data)
        self.mujoco.mj_forward(self.model, self.data)
        self.renderer.update_scene(self.data, camera="track")
        self.writer.append_data(self.renderer.render())
        self.frames += 1

    def close(self) -> None:
        self.writer.close()
        self.renderer.close()


class TrainingVideo:
    """A clip of robot 0 of the training env every `interval` iterations: <run>/videos/iter_<it>.mp4.

    A clip starts with the first env step of iteration `it` (it % interval == 0) and lasts `length_s`
    simulated seconds, across iterations when the rollout is shorter. It is written to a temporary
    file and moved into the run folder when complete, so rsl-rl's logger (which uploads every new
    mp4 of the run folder to W&B once per name) never sees a partial clip.
    """

    def __init__(self, sim, dt: float, interval: int, length_s: float):
        if interval < 1 or length_s <= 0:
            raise ConfigError(f"--video takes an iteration interval >= 1 and --video_length seconds > 0, "
                              f"got {interval} and {length_s:g}")
        self.sim, self.dt, self.interval = sim, dt, interval
        self.folder = ""  # <run>/videos, set by `write_into`
        self.length = max(1, round(length_s / dt))
        self.tmp_dir = tempfile.mkdtemp(prefix="orcgym_video_")
        self.recorder: VideoRecorder | None = None
        self.name = ""
        self.step = 0
        self.saved: list[str] = []
        try:  # fail now, not at the first clip, when offscreen rendering cannot work here
            VideoRecorder(sim, dt, os.path.join(self.tmp_dir, "probe.mp4")).close()
        except Exception:
            shutil.rmtree(self.tmp_dir, ignore_errors=True)
            raise

    def write_into(self, run_dir: str) -> None:
        self.folder = os.path.join(run_dir, VIDEO_DIR)

    def start_iteration(self, it: int) -> None:
        if self.recorder is None and self.folder and it % self.interval == 0:
            self.name = f"iter_{it:06d}.mp4"
            self.recorder = VideoRecorder(self.sim, self.dt, os.path.join(self.tmp_dir, self.name))
            self.step = 0

    def after_step(self) -> None:
        if self.recorder is None:
            return
        self.recorder.capture(self.step)
        self.step += 1
        if self.step >= self.length:
            self._finish()

    def close(self) -> str | None:
        """At the end of training: keep a clip cut short (returns its path), then drop the temporary folder."""
        cut_short = self._finish() if self.recorder is not None else None
        shutil.rmtree(self.tmp_dir, ignore_errors=True)
        return cut_short

    def _finish(self) -> str:
        self.recorder.close()
        os.makedirs(self.folder, exist_ok=True)
        target = os.path.join(self.folder, self.name)
        shutil.move(self.recorder.path, target)
        self.saved.append(target)
        self.recorder = None
        return target
