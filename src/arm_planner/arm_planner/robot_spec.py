"""Which actuators, joints and bodies of a compiled model make up the robot the planner drives."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np


@dataclass
class RobotSpec:
    """Names of the robot's parts in a MuJoCo model.

    arm_joints: arm joint names in controller order; each has a position actuator whose ctrl is the
    joint angle target. gripper_actuator: ctrl value `gripper_open` / `gripper_closed`.
    tcp_body / tcp_offset_m: the grasp point (between the fingertips) in that body's frame.
    trajectory_joints: joint names of the published JointTrajectory, one per actuator in
    `trajectory_actuators` order (the gripper included).
    finger_gap_open_m / fingertip_to_palm_m / tcp_above_fingertip_m: the open fingers' inner gap, their
    length below the palm and the TCP's height above their tips (metres); with a gap of 0 the planner
    pushes with one finger only (no caging push). finger_thickness_m / finger_width_m: each finger's
    size along and across the closing axis (metres); with 0 the planner does not turn the closing
    axis to keep the fingers off neighbouring objects.
    """

    arm_joints: tuple[str, ...]
    gripper_actuator: str
    gripper_open: float
    gripper_closed: float
    tcp_body: str
    tcp_offset_m: tuple[float, float, float]
    max_joint_rate_rad_s: float = 1.5
    max_gripper_rate: float = 1.0
    trajectory_joint_names: tuple[str, ...] = ()
    finger_gap_open_m: float = 0.0
    fingertip_to_palm_m: float = 0.0
    tcp_above_fingertip_m: float = 0.0
    finger_thickness_m: float = 0.0
    finger_width_m: float = 0.0

    def resolve(self, model: mujoco.MjModel) -> ResolvedRobot:
        return ResolvedRobot(model, self)


class ResolvedRobot:
    """RobotSpec bound to model indices."""

    def __init__(self, model: mujoco.MjModel, spec: RobotSpec):
        self.spec = spec
        self.joint_ids = np.array([_id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in spec.arm_joints])
        self.qpos_adr = model.jnt_qposadr[self.joint_ids].copy()
        self.dof_adr = model.jnt_dofadr[self.joint_ids].copy()
        actuator_by_joint = {
            int(model.actuator_trnid[a, 0]): a
            for a in range(model.nu)
            if model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT
        }
        missing = [n for n, j in zip(spec.arm_joints, self.joint_ids, strict=True) if int(j) not in actuator_by_joint]
        if missing:
            raise ValueError(f"arm joints without a position actuator: {missing}")
        self.arm_actuators = np.array([actuator_by_joint[int(j)] for j in self.joint_ids])
        self.gripper_actuator = _id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, spec.gripper_actuator)
        self.tcp_body = _id(model, mujoco.mjtObj.mjOBJ_BODY, spec.tcp_body)
        rates = np.full(model.nu, spec.max_joint_rate_rad_s)
        rates[self.gripper_actuator] = spec.max_gripper_rate
        self.max_rate = rates
        self.actuators = np.append(self.arm_actuators, self.gripper_actuator)

    def control_from_joints(self, arm_q: np.ndarray, gripper_closed: bool, nu: int) -> np.ndarray:
        ctrl = np.zeros(nu)
        ctrl[self.arm_actuators] = arm_q
        ctrl[self.gripper_actuator] = self.spec.gripper_closed if gripper_closed else self.spec.gripper_open
        return ctrl


def _id(model: mujoco.MjModel, kind: mujoco.mjtObj, name: str) -> int:
    i = mujoco.mj_name2id(model, kind, name)
    if i < 0:
        raise ValueError(f"{kind.name.removeprefix('mjOBJ_').lower()} {name!r} not in the model")
    return i
