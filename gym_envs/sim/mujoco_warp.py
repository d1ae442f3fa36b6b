"""GPU backend: MuJoCo Warp (MJWarp), every env a "world" of one batched model, float32 on the device.

Same interface and semantics as the CPU backend (`mujoco_batch.py`); what differs:

* Memory. The MJWarp model and data live on the Warp device and never leave it: the
  state, the controls and the per-env model fields are read and written through torch
  views of the Warp arrays (`wp.to_torch`, no copies). The results handed to the task
  are fresh tensors (copies on the device), so they do not change under the task's feet
  at the next step, as with the CPU backend.
* The substep loop. One control step is `num_substeps` of `mujoco_warp.step`, each
  followed by a small kernel of ours that records the foot force norms and the servo
  torques of that substep into (N, S, F) and (N, S, J) buffers, then one kernel that
  checks for divergence and puts blown-up envs back to the keyframe. On CUDA the
  whole control step (after the control copy) is captured once per substep count as a
  CUDA graph and replayed; the first step with a given count runs eagerly (it compiles
  the kernels; capture needs them loaded). Eager stepping is ~13x slower (MJWarp's own
  figures) and syncs the host in every solver iteration (`capture_while` without a graph),
  so it is never a silent fallback: the preconditions are checked at construction, one
  line says whether graphs run and why, and a device that cannot run them, or a failed
  capture, raises unless the user chose eager stepping (`cuda_graphs=False`).
* Contact forces. MJWarp 4.0 evaluates contact sensors with reduce="netforce" itself
  (`sensor.py`, reduce == 3), so the model's foot/base force sensors are read from
  `sensordata` exactly as on the CPU; nothing is recomputed from the contact arrays.
* Divergence. MJWarp does not raise or reset on a bad state. After every substep the
  record kernel flags envs with a non-finite or runaway state (|qpos| > 1e4 or
  |qvel| > 1e4, or non-finite recorded forces); those are reset to the 'home' keyframe
  at the end of the control step, their records zeroed, and reported in
  StepResult.diverged. No host synchronisation is needed for this.
* Resets. MJWarp's `reset_data_keyframe` builds its kernels in Python on every call
  (about 9 ms each), too slow for per-step resets, so resets use one kernel of ours,
  shared with the divergence rescue: it writes the keyframe's qpos, qvel, act, ctrl and
  time and clears the warm start (qacc_warmstart) and applied forces, which is the whole
  state MJWarp carries from one step to the next for models without mocap bodies,
  history buffers, plastic joints or sleeping (refused at construction).
* Randomisation. Floor friction, base mass and base CoM are batched model fields
  (`put_model(batch_sizes=...)`), one row per env, written through torch views. A mass
  or CoM change runs `mujoco_warp.set_const` (all envs at once; the derived fields it
  writes, subtree masses and inverse weights, are batched too so each env gets its own).
"""

from __future__ import annotations

import contextlib
import gc

import mujoco
import numpy as np
import torch

from gym_envs.sim.backend import SimSetupError, SimState, StepResult
from gym_envs.sim.mujoco_model import MujocoModelBackend, as_index

try:
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING  # no line per kernel module loaded; warnings and errors still show
    import mujoco_warp as mjw
except ImportError:
    raise SimSetupError("the 'warp' backend needs the gpu extra: pip install -e .[gpu]") from None

# A state past these is a blown-up simulation (MJWarp keeps stepping NaNs and giant numbers).
MAX_ABS_QPOS = 1e4  # [m] or [rad]; a legged robot never gets 10 km from the origin in an episode
MAX_ABS_QVEL = 1e4  # [m/s] or [rad/s]; the servos' joints stay below ~50 rad/s when the physics is sane

# Model fields with one row per env: those the randomisation writes, and those set_const
# derives from them (so that each env keeps its own after a mass or CoM change).
_PER_ENV_FIELDS = (
    "geom_friction",
    "body_mass",
    "body_ipos",
    "body_subtreemass",
    "body_invweight0",
    "dof_invweight0",
    "actuator_acc0",
)

# Upper bound on the contacts of a geom against a plane in MJWarp's primitive colliders.
_PLANE_CONTACTS = {
    int(mujoco.mjtGeom.mjGEOM_SPHERE): 1,
    int(mujoco.mjtGeom.mjGEOM_ELLIPSOID): 1,
    int(mujoco.mjtGeom.mjGEOM_CAPSULE): 2,
    int(mujoco.mjtGeom.mjGEOM_CYLINDER): 4,
    int(mujoco.mjtGeom.mjGEOM_BOX): 4,
}
_OTHER_PAIR_CONTACTS = 8  # generous bound for any other pair (meshes, box-box)

# MJWarp's solver loop is a `capture_while`: a conditional graph node, which needs CUDA driver 12.4.
GRAPH_MIN_DRIVER = (12, 4)
EAGER_OPT_IN = "sim.cuda_graphs=false runs eagerly (~13x slower)"


# --- kernels ------------------------------------------------------------------------------------


@wp.struct
class _Home:
    """The 'home' keyframe a reset writes."""

    qpos: wp.array(dtype=wp.float32)
    qvel: wp.array(dtype=wp.float32)
    act: wp.array(dtype=wp.float32)
    ctrl: wp.array(dtype=wp.float32)
    time: float


@wp.struct
class _WorldState:
    """Every MJWarp data field carried from one step to the next for the models we accept."""

    qpos: wp.array2d(dtype=wp.float32)
    qvel: wp.array2d(dtype=wp.float32)
    act: wp.array2d(dtype=wp.float32)
    ctrl: wp.array2d(dtype=wp.float32)
    qacc_warmstart: wp.array2d(dtype=wp.float32)
    qfrc_applied: wp.array2d(dtype=wp.float32)
    xfrc_applied: wp.array2d(dtype=wp.spatial_vector)
    time: wp.array(dtype=wp.float32)


@wp.func
def _reset_world(
    w: int,
    home: _Home,
    state: _WorldState,
    termination: wp.array(dtype=wp.float32),
):
    for i in range(state.qpos.shape[1]):
        state.qpos[w, i] = home.qpos[i]
    for i in range(state.qvel.shape[1]):
        state.qvel[w, i] = home.qvel[i]
        state.qacc_warmstart[w, i] = 0.0
        state.qfrc_applied[w, i] = 0.0
    for i in range(state.act.shape[1]):
        state.act[w, i] = home.act[i]
    for i in range(state.ctrl.shape[1]):
        state.ctrl[w, i] = home.ctrl[i]
    for b in range(state.xfrc_applied.shape[1]):
        state.xfrc_applied[w, b] = wp.spatial_vector(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    state.time[w] = home.time
    termination[w] = 0.0


@wp.kernel
def _reset_masked(
    mask: wp.array(dtype=wp.bool),
    home: _Home,
    state: _WorldState,
    termination: wp.array(dtype=wp.float32),
):
    w = wp.tid()
    if mask[w]:
        _reset_world(w, home, state, termination)


@wp.kernel
def _record_substep(
    substep: int,
    sensordata: wp.array2d(dtype=wp.float32),
    actuator_force: wp.array2d(dtype=wp.float32),
    qpos: wp.array2d(dtype=wp.float32),
    qvel: wp.array2d(dtype=wp.float32),
    foot_adr: wp.array(dtype=wp.int32),
    max_qpos: float,
    max_qvel: float,
    foot_forces: wp.array3d(dtype=wp.float32),
    joint_torques: wp.array3d(dtype=wp.float32),
    bad: wp.array(dtype=wp.int32),
):
    """After substep `substep`: store its foot force norms and servo torques, flag blown-up envs."""
    w = wp.tid()
    ok = bool(True)
    for f in range(foot_adr.shape[0]):
        a = foot_adr[f]
        norm = wp.length(wp.vec3(sensordata[w, a], sensordata[w, a + 1], sensordata[w, a + 2]))
        ok = ok and wp.isfinite(norm)
        foot_forces[w, substep, f] = norm
    for j in range(actuator_force.shape[1]):
        tau = actuator_force[w, j]
        ok = ok and wp.isfinite(tau)
        joint_torques[w, substep, j] = tau
    for i in range(qpos.shape[1]):
        x = qpos[w, i]
        ok = ok and wp.isfinite(x) and wp.abs(x) <= max_qpos
    for i in range(qvel.shape[1]):
        v = qvel[w, i]
        ok = ok and wp.isfinite(v) and wp.abs(v) <= max_qvel
    if not ok:
        bad[w] = 1


@wp.kernel
def _finish_step(
    bad: wp.array(dtype=wp.int32),
    sensordata: wp.array2d(dtype=wp.float32),
    termination_adr: wp.array(dtype=wp.int32),
    home: _Home,
    state: _WorldState,
    foot_forces: wp.array3d(dtype=wp.float32),
    joint_torques: wp.array3d(dtype=wp.float32),
    termination: wp.array(dtype=wp.float32),
    diverged: wp.array(dtype=wp.bool),
):
    """End of a control step: the termination force of the last substep, or the rescue of a blown-up env."""
    w = wp.tid()
    if bad[w] != 0:
        diverged[w] = True
        _reset_world(w, home, state, termination)
        for s in range(foot_forces.shape[1]):
            for f in range(foot_forces.shape[2]):
                foot_forces[w, s, f] = 0.0
            for j in range(joint_torques.shape[2]):
                joint_torques[w, s, j] = 0.0
        return
    diverged[w] = False
    largest = float(0.0)
    for k in range(termination_adr.shape[0]):
        a = termination_adr[k]
        largest = wp.max(largest, wp.length(wp.vec3(sensordata[w, a], sensordata[w, a + 1], sensordata[w, a + 2])))
    termination[w] = largest


# --- backend ------------------------------------------------------------------------------------


class MujocoWarpBackend(MujocoModelBackend):
    """`num_envs` worlds of one MJWarp model; the same arguments and results as `MujocoBatchBackend`.

    device: where the task's tensors live. warp_device: where the simulation runs, by default
    the same device ('cuda:i' for a torch 'cuda:i', else Warp's 'cpu'). num_threads is
    accepted for the CPU backend's sake and ignored. cuda_graphs: replay each control step
    as a captured CUDA graph (CUDA only); False chooses eager stepping. `graph_status` is the
    line printed at construction: graphs on or off, and why.
    """

    def __init__(
        self,
        model_path: str,
        num_envs: int,
        foot_sensors: tuple[str, ...],
        termination_sensors: tuple[str, ...],
        ground_geom: str = "floor",
        base_body: str = "base",
        device: str | torch.device = "cpu",
        num_threads: int = 0,  # the CPU backend's knob; Warp schedules its own threads
        warp_device: str | None = None,
        cuda_graphs: bool = True,
    ):
        self.device = torch.device(device)
        if self.device.type == "cuda" and not torch.cuda.is_available():
            raise SimSetupError(f"device {str(device)!r} asked for, but torch has no CUDA device here")
        self._wp_device = _warp_device(self.device, warp_device)
        m = self._read_model(model_path, num_envs, foot_sensors, termination_sensors, ground_geom, base_body)
        _check_state_is_covered(m, model_path)

        # --- the Warp side
        self._cuda = self._wp_device.is_cuda
        self._view_device = torch.device(wp.device_to_torch(self._wp_device))
        self._stream = wp.get_stream(self._wp_device) if self._cuda else None
        self._torch_streams: dict[int, object] = {}  # torch stream handle -> the same stream as a wp.Stream
        with self._warp_work():
            try:
                self.warp_model = mjw.put_model(m, batch_sizes=_batch_sizes(m, num_envs))
            except NotImplementedError as err:
                raise SimSetupError(f"MuJoCo Warp cannot simulate {model_path!r}: {err}") from None
            # The scene caps the line search on purpose (ls_iterations, as the CPU backend runs it, which does not
            # warn); Warp would print two lines each time a world reaches it, hundreds per training iteration on
            # a GPU. Every other overflow (contacts, constraints) still warns.
            self.warp_model.opt.warn_overflow &= ~int(mjw.OverflowType.LS_ITERATIONS)
            nconmax, njmax = _constraint_capacity(m)
            self.warp_data = mjw.make_data(m, nworld=num_envs, nconmax=nconmax, njmax=njmax)
            home = self._home_key
            self._home_struct = _Home()
            for name, values in (("qpos", m.key_qpos), ("qvel", m.key_qvel), ("act", m.key_act), ("ctrl", m.key_ctrl)):
                setattr(self._home_struct, name, wp.array(np.asarray(values[home], dtype=np.float32).ravel(),
                                                          dtype=wp.float32))
            self._home_struct.time = float(m.key_time[home])
            d = self.warp_data
            self._state_struct = _WorldState()
            for name in ("qpos", "qvel", "act", "ctrl", "qacc_warmstart", "qfrc_applied", "xfrc_applied", "time"):
                setattr(self._state_struct, name, getattr(d, name))
            self._foot_adr = wp.array(self._foot_rows[:, 0].astype(np.int32), dtype=wp.int32)
            self._termination_adr = wp.array(self._termination_rows[:, 0].astype(np.int32), dtype=wp.int32)
            self._bad = wp.zeros(num_envs, dtype=wp.int32)
            self._diverged = wp.zeros(num_envs, dtype=wp.bool)
            self._termination = wp.zeros(num_envs, dtype=wp.float32)
            self._reset_mask = wp.zeros(num_envs, dtype=wp.bool)

        d, mw = self.warp_data, self.warp_model
        # Torch views of the Warp arrays (shared memory, on the Warp device).
        self._qpos_t = wp.to_torch(d.qpos)
        self._qvel_t = wp.to_torch(d.qvel)
        self._ctrl_t = wp.to_torch(d.ctrl)
        self._termination_t = wp.to_torch(self._termination)
        self._diverged_t = wp.to_torch(self._diverged)
        self._reset_mask_t = wp.to_torch(self._reset_mask)
        self._friction_t = wp.to_torch(mw.geom_friction)  # (N, ngeom, 3)
        self._mass_t = wp.to_torch(mw.body_mass)  # (N, nbody)
        self._ipos_t = wp.to_torch(mw.body_ipos)  # (N, nbody, 3)
        self._joint_qpos_t = torch.as_tensor(self._joint_qpos, device=self._view_device)
        self._joint_qvel_t = torch.as_tensor(self._joint_qvel, device=self._view_device)

        self._records: dict[int, tuple] = {}  # substeps -> (foot_forces wp, joint_torques wp, torch views)
        self._use_graphs, reason = graph_decision(
            self._cuda, wp.get_cuda_driver_version(), self._cuda and wp.is_mempool_enabled(self._wp_device), cuda_graphs
        )
        if cuda_graphs and self._cuda and not self._use_graphs:
            raise SimSetupError(f"CUDA graphs cannot run on {self._wp_device}: {reason}; {EAGER_OPT_IN}")
        self.graph_status = f"warp on {self._wp_device}: CUDA graphs {'on' if self._use_graphs else 'off'} ({reason})"
        print(self.graph_status, flush=True)
        self._graphs: dict[int, object] = {}
        self._stepped_eagerly: set[int] = set()
        self._reset_to_home(torch.arange(self.num_envs, device=self._view_device))

    @property
    def num_threads(self) -> int:
        return 0  # not a knob here: Warp runs the kernels

    # --- stepping -------------------------------------------------------------------------------

    def step(self, joint_targets: torch.Tensor, num_substeps: int) -> StepResult:
        if joint_targets.shape != (self.num_envs, self.num_joints):
            raise ValueError(
                f"joint targets must have shape ({self.num_envs}, {self.num_joints}) = (num_envs, num_joints), "
                f"got {tuple(joint_targets.shape)}"
            )
        if num_substeps < 1:
            raise ValueError(f"num_substeps must be at least 1, got {num_substeps}")
        self._ctrl_t.copy_(joint_targets.detach())
        forces_t, torques_t = self._record_buffers(num_substeps)[2:]
        with self._warp_work():
            self._advance(num_substeps)
        return StepResult(
            state=self.read_state(),
            foot_forces=forces_t.to(self.device, copy=True),
            joint_torques=torques_t.to(self.device, copy=True),
            diverged=self._diverged_t.to(self.device, copy=True),
        )

    def _advance(self, num_substeps: int) -> None:
        """Launch one control step: captured as a CUDA graph after its first, eager, run."""
        if self._use_graphs and num_substeps in self._stepped_eagerly:
            graph = self._graphs.get(num_substeps)
            if graph is None:
                graph = self._capture(num_substeps)
            wp.capture_launch(graph, stream=self._stream)
            return
        self._launch_control_step(num_substeps)
        self._stepped_eagerly.add(num_substeps)

    def _capture(self, num_substeps: int):
        # A collection during capture can run a stale graph's destructor, recorded into the new
        # graph, which then frees memory on replay: no collections until the capture ends.
        collecting = gc.isenabled()
        gc.disable()
        try:
            # The eager run before loaded every module the step uses; loading all of MJWarp's is not needed.
            with wp.ScopedCapture(device=self._wp_device, stream=self._stream, force_module_load=False) as capture:
                self._launch_control_step(num_substeps)
        except Exception as err:  # a host read inside the kernel chain, an allocation the pool refused
            raise SimSetupError(f"CUDA graph capture of the control step failed on {self._wp_device}: {err}; "
                                f"{EAGER_OPT_IN}") from err
        finally:
            if collecting:
                gc.enable()
        self._graphs[num_substeps] = capture.graph
        return capture.graph

    def _launch_control_step(self, num_substeps: int) -> None:
        m, d = self.warp_model, self.warp_data
        forces, torques = self._record_buffers(num_substeps)[:2]
        self._bad.zero_()
        for s in range(num_substeps):
            mjw.step(m, d)
            wp.launch(
                _record_substep,
                dim=self.num_envs,
                inputs=[s, d.sensordata, d.actuator_force, d.qpos, d.qvel, self._foot_adr, MAX_ABS_QPOS, MAX_ABS_QVEL],
                outputs=[forces, torques, self._bad],
            )
        wp.launch(
            _finish_step,
            dim=self.num_envs,
            inputs=[self._bad, d.sensordata, self._termination_adr, self._home_struct, self._state_struct],
            outputs=[forces, torques, self._termination, self._diverged],
        )

    def _record_buffers(self, num_substeps: int) -> tuple:
        bufs = self._records.get(num_substeps)
        if bufs is None:
            with self._warp_work():
                forces = wp.zeros((self.num_envs, num_substeps, len(self.foot_names)), dtype=wp.float32)
                torques = wp.zeros((self.num_envs, num_substeps, self.num_joints), dtype=wp.float32)
            bufs = (forces, torques, wp.to_torch(forces), wp.to_torch(torques))
            self._records[num_substeps] = bufs
        return bufs

    def read_state(self) -> SimState:
        qpos = self._qpos_t.to(self.device, copy=True)
        qvel = self._qvel_t.to(self.device, copy=True)
        p, v = self._root_qpos, self._root_qvel
        return SimState(
            base_pos=qpos[:, p : p + 3],
            base_quat=qpos[:, p + 3 : p + 7],
            base_lin_vel=qvel[:, v : v + 3],  # a free joint's linear velocity is in the world frame
            base_ang_vel=qvel[:, v + 3 : v + 6],  # and its angular velocity in the body frame
            joint_pos=qpos[:, self._joint_qpos_t.to(self.device)],
            joint_vel=qvel[:, self._joint_qvel_t.to(self.device)],
            termination_force=self._termination_t.to(self.device, copy=True),
        )

    # --- resets and perturbations ---------------------------------------------------------------

    def reset(self, env_ids, base_pos, base_quat, base_lin_vel, base_ang_vel, joint_pos, joint_vel) -> None:
        ids = self._ids(env_ids)
        if ids.numel() == 0:
            return
        # Keyframe first (time, warm starts, actuator state, applied forces), then the given state.
        self._reset_to_home(ids)
        p, v = self._root_qpos, self._root_qvel
        self._qpos_t[ids, p : p + 3] = self._values(base_pos)
        self._qpos_t[ids, p + 3 : p + 7] = self._values(base_quat)
        self._qpos_t[ids[:, None], self._joint_qpos_t] = self._values(joint_pos)
        self._qvel_t[ids, v : v + 3] = self._values(base_lin_vel)
        self._qvel_t[ids, v + 3 : v + 6] = self._values(base_ang_vel)
        self._qvel_t[ids[:, None], self._joint_qvel_t] = self._values(joint_vel)

    def push_base(self, env_ids, delta_vel_xy) -> None:
        ids = self._ids(env_ids)
        v = self._root_qvel
        self._qvel_t[ids, v : v + 2] += self._values(delta_vel_xy)

    def set_ground_friction(self, env_ids, friction) -> None:
        ids = self._ids(env_ids)
        self._friction_t[ids, self._ground_geom, 0] = self._values(friction)

    def set_base_mass_offset(self, env_ids, added_mass) -> None:
        ids = self._ids(env_ids)
        self._mass_t[ids, self._base_body] = float(self.model.body_mass[self._base_body]) + self._values(added_mass)
        self._set_const()  # subtree masses and the inverse weights follow the new mass

    def set_base_com_offset(self, env_ids, offset) -> None:
        ids = self._ids(env_ids)
        base_ipos = torch.as_tensor(self.model.body_ipos[self._base_body], dtype=torch.float32, device=self._view_device)
        self._ipos_t[ids, self._base_body] = base_ipos + self._values(offset)
        self._set_const()

    def copy_state_to(self, env_id: int, data: mujoco.MjData) -> None:
        data.qpos[:] = self._qpos_t[env_id].cpu().numpy()
        data.qvel[:] = self._qvel_t[env_id].cpu().numpy()

    def ground_friction(self) -> np.ndarray:
        """Per-env floor friction as the physics sees it (for tests and logs)."""
        return self._friction_t[:, self._ground_geom, 0].cpu().numpy().astype(np.float64)

    # --- helpers --------------------------------------------------------------------------------

    @contextlib.contextmanager
    def _warp_work(self):
        """Run Warp work on our device, ordered after and before the torch work on the same arrays.

        On CUDA, Warp launches go to Warp's stream of the device (where the graphs are captured)
        and torch works on its current stream: each block of Warp work waits for torch's
        stream and makes torch's stream wait for it.
        """
        if not self._cuda:
            with wp.ScopedDevice(self._wp_device):
                yield
            return
        current = torch.cuda.current_stream(self._view_device)
        torch_stream = self._torch_streams.get(current.cuda_stream)
        if torch_stream is None:
            torch_stream = self._torch_streams[current.cuda_stream] = wp.stream_from_torch(current)
        self._stream.wait_stream(torch_stream)
        with wp.ScopedStream(self._stream):
            yield
        torch_stream.wait_stream(self._stream)

    def _reset_to_home(self, ids: torch.Tensor) -> None:
        self._reset_mask_t.zero_()
        self._reset_mask_t[ids] = True
        with self._warp_work():
            wp.launch(
                _reset_masked,
                dim=self.num_envs,
                inputs=[self._reset_mask, self._home_struct, self._state_struct],
                outputs=[self._termination],
            )

    def _set_const(self) -> None:
        with self._warp_work():
            mjw.set_const(self.warp_model, self.warp_data, groups=mjw.SetConstGroup.FIXED | mjw.SetConstGroup.INERT0)

    def _ids(self, env_ids) -> torch.Tensor:
        if isinstance(env_ids, torch.Tensor):  # stays on the device: no host round trip
            return env_ids.detach().to(self._view_device, torch.int64).reshape(-1)
        return torch.as_tensor(as_index(env_ids), device=self._view_device)

    def _values(self, values) -> torch.Tensor:
        return torch.as_tensor(values, dtype=torch.float32, device=self._view_device)



def graph_decision(is_cuda: bool, driver: tuple[int, int] | None, mempool_enabled: bool,
                   requested: bool) -> tuple[bool, str]:
    """Whether the control step runs as a CUDA graph, and why (for the status line)."""
    if not requested:
        return False, f"eager by request: {EAGER_OPT_IN}"
    needs = f"driver >= {GRAPH_MIN_DRIVER[0]}.{GRAPH_MIN_DRIVER[1]} and Warp's memory pool"
    if not is_cuda:
        return False, f"Warp's CPU device; a CUDA device would use them given {needs}"
    missing = []
    if driver is None or driver < GRAPH_MIN_DRIVER:
        missing.append("no CUDA driver version" if driver is None else f"driver {driver[0]}.{driver[1]}")
    if not mempool_enabled:
        missing.append("memory pool off")
    if missing:
        return False, f"{', '.join(missing)}; graphs need {needs}"
    return True, f"driver {driver[0]}.{driver[1]}, memory pool on"


def _warp_device(device: torch.device, warp_device: str | None):
    """The Warp device: the one named, else the task's device (cuda:i -> cuda:i, anything else -> cpu)."""
    if warp_device is None:
        warp_device = f"cuda:{device.index or 0}" if device.type == "cuda" else "cpu"
    try:
        return wp.get_device(warp_device)
    except (RuntimeError, ValueError) as err:
        raise SimSetupError(f"Warp has no device {warp_device!r} on this machine: {err}") from None


def _batch_sizes(model: mujoco.MjModel, num_envs: int) -> dict[str, int]:
    sizes = {name: num_envs for name in _PER_ENV_FIELDS}
    if model.ntendon:
        sizes["tendon_invweight0"] = num_envs
    return sizes


def _check_state_is_covered(model: mujoco.MjModel, model_path: str) -> None:
    """Our reset kernel writes qpos, qvel, act, ctrl, warm starts and applied forces; refuse models with more state."""
    extra = {
        "mocap bodies": model.nmocap,
        "history buffers": getattr(model, "nhistory", 0),
        "plastic joints": getattr(model, "nplastic", 0),
        "equality constraints": model.neq,
        "sleeping": model.opt.enableflags & mujoco.mjtEnableBit.mjENBL_SLEEP,
    }
    found = [name for name, count in extra.items() if count]
    if found:
        raise SimSetupError(f"the 'warp' backend does not reset models with {', '.join(found)} ({model_path!r})")


def _constraint_capacity(model: mujoco.MjModel) -> tuple[int, int]:
    """(contacts, constraint rows) per world that the model can ever need, from its colliding geom pairs.

    Contacts: for every geom pair that may collide (contype/conaffinity, different bodies), MJWarp's
    most contacts for that pair type against a plane, or a generous 8 otherwise. Rows: each contact
    takes 2 (condim - 1) rows with a pyramidal cone (condim with an elliptic one), plus one per
    limited joint or tendon and per dof with friction loss, plus 6 per equality constraint.
    """
    m = model
    plane = int(mujoco.mjtGeom.mjGEOM_PLANE)
    ncon = 0
    for g1 in range(m.ngeom):
        for g2 in range(g1 + 1, m.ngeom):
            if not (m.geom_contype[g1] & m.geom_conaffinity[g2] or m.geom_contype[g2] & m.geom_conaffinity[g1]):
                continue
            if m.body_weldid[m.geom_bodyid[g1]] == m.body_weldid[m.geom_bodyid[g2]]:
                continue
            t1, t2 = int(m.geom_type[g1]), int(m.geom_type[g2])
            if t1 == plane or t2 == plane:
                ncon += _PLANE_CONTACTS.get(t2 if t1 == plane else t1, _OTHER_PAIR_CONTACTS)
            else:
                ncon += _OTHER_PAIR_CONTACTS
    ncon += _OTHER_PAIR_CONTACTS * m.npair
    condim = int(m.geom_condim.max(initial=1))
    rows_per_contact = max(1, 2 * (condim - 1)) if m.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL else condim
    rows = ncon * rows_per_contact + int(m.jnt_limited.sum()) + int(m.tendon_limited.sum())
    rows += int((m.dof_frictionloss > 0).sum()) + 6 * m.neq
    return max(ncon, 1), max(rows, 1)
