"""Deployment export: the policy with the facts a robot needs, and the whole controller as one ONNX graph.

`export_deployment` writes to a folder:
  * policy.pt (TorchScript) and policy.onnx: the deterministic actor, normaliser included; input the
    env-scaled actor observation (batch 1 for ONNX), output the actions;
  * controller.onnx (tasks with oscillators): observation building, the oscillators and the policy
    in one graph, so a robot runs it on its raw readings (see `Controller`).
Both ONNX files carry the same metadata (`metadata_props` key `orcgym`, a JSON object): observation
terms in order with their widths and scales, action scale and clip, default joint positions, joint
names, the servos' Kp/Kd and torque limits, control and physics rates, and for oscillator tasks the
ORC string and the oscillator constants. `read_metadata(path)` returns it as a dict.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import os
import warnings
from types import SimpleNamespace

import torch
from torch import nn

from gym_envs import oscillators
from gym_envs.config import ConfigError

METADATA_KEY = "orcgym"
POLICY_JIT, POLICY_ONNX, CONTROLLER_ONNX = "policy.pt", "policy.onnx", "controller.onnx"
# Controller inputs and outputs, in graph order, with their meaning (also written to the metadata).
CONTROLLER_INPUTS = {
    "base_ang_vel": "(1, 3) base angular velocity, body frame [rad/s] (gyroscope)",
    "projected_gravity": "(1, 3) unit gravity direction in the body frame (from the IMU orientation)",
    "joint_pos": "(1, J) joint positions [rad], model actuator order",
    "joint_vel": "(1, J) joint velocities [rad/s]",
    "previous_joint_targets": "(1, J) the joint targets sent at the last tick [rad] (the default pose after a reset)",
    "foot_forces": "(1, decimation, legs) norm of each foot's contact force [N] at every physics substep of the "
                   "last control period, oldest first (zeros before the first period)",
    "command": "(1, 3) v_x [m/s], v_y [m/s], yaw rate [rad/s], body frame",
    "phase": "(1, legs) oscillator phases [rad] before the last control period (the controller's last output)",
}
CONTROLLER_OUTPUTS = {
    "joint_targets": "(1, J) joint position targets [rad] for the PD servos",
    "new_phase": "(1, legs) phases after integrating the last period's foot forces; feed back as `phase`",
}


def deployment_metadata(task, checkpoint: str = "") -> dict:
    """Everything outside the networks that a robot needs to run the policy, as plain JSON values."""
    cfg, model = task.cfg, task.sim.model

    def floats(t) -> list[float]:
        return [float(v) for v in torch.as_tensor(t, device="cpu").flatten()]

    meta = {
        "task": type(task).__name__,
        "checkpoint": os.path.basename(checkpoint),
        "observation": [{"term": name, "width": len(scale), "scale": floats(scale)}
                        for name, scale in task.observation_scales("actor").items()],
        "observation_rule": "each term is divided by its scale, then concatenated in this order",
        "action_scale": floats(task.action_scale),
        "clip_actions": float(cfg.control.clip_actions),
        "joint_targets_rule": "default_joint_pos + action_scale * clip(action, -clip_actions, clip_actions)",
        "joint_names": list(task.sim.joint_names),
        "default_joint_pos": floats(task.default_joint_pos),
        # MuJoCo position actuators: gain kp, bias (0, -kp, -kv).
        "kp": floats(model.actuator_gainprm[:, 0]),
        "kd": floats(-model.actuator_biasprm[:, 2]),
        "torque_limit": floats(model.actuator_forcerange[:, 1]),
        "control_hz": 1.0 / task.dt,
        "physics_hz": 1.0 / task.physics_dt,
        "decimation": int(task.decimation),
    }
    osc = getattr(cfg, "osc", None)
    if osc is not None:
        meta["oscillators"] = {
            "orc": osc.orc,
            "legs": list(oscillators.LEG_NAMES),
            "equation": "dphi/dt = 2 pi (omega - sigma * GRF * (cos(phi) + xi)), explicit Euler per physics substep",
            "grf_rule": "GRF = clip(foot force / grf_normaliser, 0, 1)",
            "grf_normaliser": float(task.grf_normaliser),
            "coupling_enabled": bool(task.orc.coupling),
            "coupling_max": float(osc.coupling_max),
            "stand_threshold": float(osc.stand_threshold),
            "standing_rule": str(osc.standing_rule),
            "standing": {"omega": oscillators.STANDING_OMEGA, "sigma": oscillators.STANDING_COUPLING,
                         "xi": oscillators.STANDING_OFFSET},
            "moving": {"omega": f"min(|v_x| + {oscillators.MOVING_OMEGA_BIAS}, {oscillators.MOVING_OMEGA_MAX})",
                       "sigma": "coupling_max", "xi": 0.0},
        }
        meta["controller"] = {"inputs": CONTROLLER_INPUTS, "outputs": CONTROLLER_OUTPUTS}
    return meta


class Controller(nn.Module):
    """Raw readings in, joint targets and new phases out: one control tick of the evaluation env, noise off.

    The tick first integrates the oscillators over the last control period's substeps (each with its
    own foot force, as in training: `oscillators.integrate_phases`), with the parameters of the
    current command (`oscillators.oscillator_params`, jitter off), then builds the actor
    observation with the task's own `_obs_<name>` terms, called on a view of the task made of the
    readings (`_task_view`), runs the policy and turns the action into joint targets. A term that
    reads anything else (simulator state a robot does not read) is refused.
    """

    def __init__(self, policy: nn.Module, task):
        super().__init__()
        cfg = task.cfg
        if getattr(cfg, "osc", None) is None:
            raise ConfigError(f"the controller export needs a task with oscillators; {type(task).__name__} has none")
        if cfg.osc.hold_grf:
            raise ConfigError("the controller export integrates each substep's own force; this run sets "
                              "osc.hold_grf=true (export the policy alone, or retrain without it)")
        scales = task.observation_scales("actor")
        self.policy = policy
        self.terms = tuple((name, getattr(type(task), f"_obs_{name}")) for name in scales)
        for name, scale in scales.items():
            self.register_buffer(f"scale_{name}", scale.detach().cpu().clone())
        self.register_buffer("default_joint_pos", task.default_joint_pos.detach().cpu().clone())
        self.register_buffer("action_scale", task.action_scale.detach().cpu().clone())
        self.clip_actions = float(cfg.control.clip_actions)
        self.physics_dt = float(task.physics_dt)
        self.decimation = int(task.decimation)
        self.num_legs = int(task.num_legs)
        self.grf_normaliser = float(task.grf_normaliser)
        self.coupling_max = float(cfg.osc.coupling_max)
        self.stand_threshold = float(cfg.osc.stand_threshold)
        self.standing_rule = str(cfg.osc.standing_rule)
        self.coupling_enabled = bool(task.orc.coupling)
        view, unreadable = self._task_view(*self.example_inputs()), []
        for name, term in self.terms:
            try:
                term(view)
            except AttributeError:  # the term reads what the readings do not give
                unreadable.append(name)
        if unreadable:
            raise ConfigError(f"actor observation terms {', '.join(unreadable)} need simulator state a robot does "
                              f"not read; the controller reads only {', '.join(CONTROLLER_INPUTS)}")

    def forward(self, *readings):  # CONTROLLER_INPUTS, in order
        view = self._task_view(*readings)
        obs = torch.cat([term(view) / getattr(self, f"scale_{name}") for name, term in self.terms], dim=1)
        actions = torch.clamp(self.policy(obs), -self.clip_actions, self.clip_actions)
        return self.default_joint_pos + actions * self.action_scale, view.phase

    def _task_view(self, base_ang_vel, projected_gravity, joint_pos, joint_vel, previous_joint_targets, foot_forces,
                   command, phase) -> SimpleNamespace:
        """Stands in for the task when its observation terms are called: the state they may read, from the
        readings (the phases integrated over the last period); any other attribute does not exist."""
        grf = torch.clamp(foot_forces / self.grf_normaliser, 0.0, 1.0)
        omega, coupling, offset = oscillators.oscillator_params(
            command[:, 0], coupling_max=self.coupling_max, stand_threshold=self.stand_threshold,
            coupling_enabled=self.coupling_enabled,
            stand_speed=oscillators.standing_speed(command, self.standing_rule),
        )
        new_phase, phase_vel = oscillators.integrate_phases(phase, grf, omega, coupling, offset, self.physics_dt)
        return SimpleNamespace(base_ang_vel=base_ang_vel, projected_gravity=projected_gravity, commands=command,
                               joint_pos=joint_pos, joint_vel=joint_vel, default_joint_pos=self.default_joint_pos,
                               target_history=(previous_joint_targets - self.default_joint_pos,), phase=new_phase,
                               phase_vel=phase_vel)

    def example_inputs(self) -> tuple[torch.Tensor, ...]:
        j, legs, dev = self.default_joint_pos.numel(), self.num_legs, self.default_joint_pos.device
        return (torch.zeros(1, 3, device=dev), torch.tensor([[0.0, 0.0, -1.0]], device=dev),
                self.default_joint_pos.reshape(1, j).clone(), torch.zeros(1, j, device=dev),
                self.default_joint_pos.reshape(1, j).clone(), torch.zeros(1, self.decimation, legs, device=dev),
                torch.zeros(1, 3, device=dev), torch.zeros(1, legs, device=dev))


@contextlib.contextmanager
def _quiet_export():
    """torch's exporters print progress and warn about optional packages they do not need."""
    onnx_logger = logging.getLogger("torch.onnx")
    level = onnx_logger.level
    onnx_logger.setLevel(logging.ERROR)
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()), \
                warnings.catch_warnings():
            warnings.simplefilter("ignore")
            yield
    finally:
        onnx_logger.setLevel(level)


def _write_onnx(model: nn.Module, inputs: tuple, path: str, input_names: list, output_names: list,
                metadata: dict) -> None:
    """Export to ONNX, fold weights the exporter put in a side file back in, and attach the metadata."""
    import onnx

    with _quiet_export(), torch.no_grad():
        torch.onnx.export(model, inputs, path, opset_version=18, input_names=input_names, output_names=output_names)
    header = onnx.load(path, load_external_data=False)
    side_files = {e.value for t in header.graph.initializer for e in t.external_data if e.key == "location"}
    model = onnx.load(path)
    del model.metadata_props[:]
    onnx.helper.set_model_props(model, {METADATA_KEY: json.dumps(metadata)})
    onnx.save_model(model, path)
    for name in side_files:
        side = os.path.join(os.path.dirname(path), os.path.basename(name))
        if os.path.isfile(side):
            os.remove(side)


def read_metadata(path: str) -> dict:
    import onnx

    props = {p.key: p.value for p in onnx.load(path, load_external_data=False).metadata_props}
    if METADATA_KEY not in props:
        raise ConfigError(f"{path} has no orcgym metadata; export it again with play.py --export")
    return json.loads(props[METADATA_KEY])


def export_deployment(policy: nn.Module, task, directory: str, checkpoint: str = "") -> list[str]:
    """Write policy.pt, policy.onnx and (oscillator tasks) controller.onnx; returns the paths written.

    policy: the trained actor (rsl-rl MLPModel, normaliser included): `learning.runs.load_policy(...).policy.model`.
    A policy with a NaN or infinite tensor is refused before anything is written: a robot would run it.
    """
    from learning.runs import non_finite_tensor

    bad = non_finite_tensor(policy.state_dict())
    if bad:
        raise ConfigError(f"not exporting {checkpoint or 'the policy'}: tensor {bad[0]} holds {bad[1]} NaN or infinite "
                          f"values; export a checkpoint whose networks are finite")
    os.makedirs(directory, exist_ok=True)
    metadata = deployment_metadata(task, checkpoint)
    paths = [os.path.join(directory, name) for name in (POLICY_JIT, POLICY_ONNX, CONTROLLER_ONNX)]
    with _quiet_export():
        torch.jit.script(policy.as_jit().cpu()).save(paths[0])
    onnx_policy = policy.as_onnx(verbose=False).cpu().eval()
    _write_onnx(onnx_policy, onnx_policy.get_dummy_inputs(), paths[1], onnx_policy.input_names,
                onnx_policy.output_names, metadata)
    if getattr(task.cfg, "osc", None) is None:
        return paths[:2]
    controller = Controller(onnx_policy, task).eval()
    _write_onnx(controller, controller.example_inputs(), paths[2], list(CONTROLLER_INPUTS), list(CONTROLLER_OUTPUTS),
                metadata)
    return paths
