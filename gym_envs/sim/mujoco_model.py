"""What both MuJoCo backends (CPU batch and Warp) read from an MJCF model, in one place.

The facts a task needs (timestep, gravity, robot mass, joints in actuator order, limits, the
'home' keyframe) and the indices a backend needs (root qpos/qvel addresses, joint addresses,
force-sensor rows, the ground geom) come from the compiled model, never from constants.
"""

from __future__ import annotations

import os

import mujoco
import numpy as np
import torch

from gym_envs.sim.backend import SimBackend, SimSetupError

HOME_KEY = "home"


def load_model(model_path: str) -> mujoco.MjModel:
    """Compile an MJCF file, turning every failure into one line that names the file."""
    if not os.path.isfile(model_path):
        raise SimSetupError(f"model file not found: {model_path!r}; check the task's sim.model_path")
    try:
        return mujoco.MjModel.from_xml_path(model_path)
    except ValueError as err:
        detail = " ".join(str(err).split())
        raise SimSetupError(f"model file {model_path!r} does not compile: {detail}") from None


class MujocoModelBackend(SimBackend):
    """Base of the MuJoCo backends: compiles the model and reads its facts and indices."""

    def _read_model(
        self,
        model_path: str,
        num_envs: int,
        foot_sensors: tuple[str, ...],
        termination_sensors: tuple[str, ...],
        ground_geom: str,
        base_body: str,
    ) -> mujoco.MjModel:
        if num_envs < 1:
            raise SimSetupError(f"num_envs must be at least 1, got {num_envs}")
        self.num_envs = num_envs
        self.model = m = load_model(model_path)
        self.timestep = float(m.opt.timestep)
        self.gravity = float(np.linalg.norm(m.opt.gravity))

        self._base_body = named_id(m, mujoco.mjtObj.mjOBJ_BODY, base_body, "body")
        root_joint = m.body_jntadr[self._base_body]
        if root_joint < 0 or m.jnt_type[root_joint] != mujoco.mjtJoint.mjJNT_FREE:
            raise SimSetupError(f"body {base_body!r} of {model_path!r} has no free joint; a legged robot needs one")
        self._root_qpos = int(m.jnt_qposadr[root_joint])
        self._root_qvel = int(m.jnt_dofadr[root_joint])
        self.robot_mass = float(m.body_subtreemass[self._base_body])

        # Joints in actuator order: the task's action order is the model's actuator order.
        if m.nu == 0:
            raise SimSetupError(f"model {model_path!r} has no actuators")
        joints = [int(m.actuator_trnid[i, 0]) for i in range(m.nu)]
        self.joint_names = tuple(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in joints)
        self._joint_qpos = np.array([m.jnt_qposadr[j] for j in joints])
        self._joint_qvel = np.array([m.jnt_dofadr[j] for j in joints])
        self.joint_pos_limits = torch.tensor(m.jnt_range[joints], dtype=torch.float32, device=self.device)
        self.torque_limits = torch.tensor(
            np.abs(m.actuator_forcerange).max(axis=1), dtype=torch.float32, device=self.device
        )
        self._home_key = named_id(m, mujoco.mjtObj.mjOBJ_KEY, HOME_KEY, "keyframe")
        home_qpos = m.key_qpos[self._home_key]
        self.default_joint_pos = torch.tensor(home_qpos[self._joint_qpos], dtype=torch.float32, device=self.device)

        self.foot_names = tuple(foot_sensors)
        self._foot_rows = force_sensor_rows(m, foot_sensors)
        self.joint_anchors, self.joint_axes, self.foot_positions = home_geometry(
            m, self._home_key, self._base_body, joints, foot_sensors
        )
        self._termination_rows = force_sensor_rows(m, termination_sensors)
        self._ground_geom = named_id(m, mujoco.mjtObj.mjOBJ_GEOM, ground_geom, "geom")
        return m

    def copy_state_to(self, env_id: int, data: mujoco.MjData) -> None:
        """Write env env_id's state into an MjData of self.model (to render or inspect it; run mj_forward after)."""
        raise NotImplementedError


def named_id(model: mujoco.MjModel, kind: mujoco.mjtObj, name: str, label: str) -> int:
    idx = mujoco.mj_name2id(model, kind, name)
    if idx < 0:
        raise SimSetupError(f"the model has no {label} named {name!r}")
    return idx


def home_geometry(model: mujoco.MjModel, key: int, base_body: int, joints: list[int], foot_sensors: tuple[str, ...]):
    """Joint anchors and axes and foot positions, (J, 3), (J, 3) and (L, 3), in the base frame at a keyframe."""
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, key)
    mujoco.mj_forward(model, data)
    origin, rotation = data.xpos[base_body], data.xmat[base_body].reshape(3, 3)
    positions = {
        mujoco.mjtObj.mjOBJ_GEOM: data.geom_xpos,
        mujoco.mjtObj.mjOBJ_SITE: data.site_xpos,
        mujoco.mjtObj.mjOBJ_BODY: data.xpos,
    }
    feet = []
    for name in foot_sensors:
        sid = named_id(model, mujoco.mjtObj.mjOBJ_SENSOR, name, "sensor")
        kind = mujoco.mjtObj(model.sensor_objtype[sid])
        if kind not in positions:
            raise SimSetupError(f"sensor {name!r} is attached to a {kind.name}; a foot sensor needs a geom, site or body")
        feet.append(positions[kind][model.sensor_objid[sid]])
    anchors = (data.xanchor[joints] - origin) @ rotation
    axes = data.xaxis[joints] @ rotation
    return anchors, axes, (np.array(feet) - origin) @ rotation


def force_sensor_rows(model: mujoco.MjModel, names: tuple[str, ...]) -> np.ndarray:
    """sensordata indices (len(names), 3) of 3-D contact-force sensors."""
    rows = []
    for name in names:
        sid = named_id(model, mujoco.mjtObj.mjOBJ_SENSOR, name, "sensor")
        if model.sensor_dim[sid] != 3:
            raise SimSetupError(f"sensor {name!r} must give a 3-D force (contact sensor with reduce='netforce')")
        adr = model.sensor_adr[sid]
        rows.append(np.arange(adr, adr + 3))
    return np.array(rows, dtype=np.int64).reshape(len(names), 3)


def as_index(env_ids) -> np.ndarray:
    """Env ids (tensor, array or list) as a flat int64 numpy array."""
    if isinstance(env_ids, torch.Tensor):
        env_ids = env_ids.detach().cpu().numpy()
    return np.asarray(env_ids, dtype=np.int64).ravel()
