"""A 7-DoF arm with Franka Panda kinematics and a parallel-jaw gripper, from primitive geoms.

Kinematics follow Franka's published modified-DH parameters (Craig convention):
T_{i-1,i} = RotX(alpha_{i-1}) TransX(a_{i-1}) RotZ(q_i) TransZ(d_i).
"""

import mujoco
import numpy as np

# (a_{i-1} m, d_i m, alpha_{i-1} rad) for joints 1..7, then the flange.
PANDA_DH = (
    (0.0, 0.333, 0.0),
    (0.0, 0.0, -np.pi / 2),
    (0.0, 0.316, np.pi / 2),
    (0.0825, 0.0, np.pi / 2),
    (-0.0825, 0.384, -np.pi / 2),
    (0.0, 0.0, np.pi / 2),
    (0.088, 0.0, np.pi / 2),
)
FLANGE_D_M = 0.107
TCP_OFFSET_M = 0.1034  # flange -> point between the fingertips
JOINT_LIMITS = np.array(
    [
        (-2.8973, 2.8973),
        (-1.7628, 1.7628),
        (-2.8973, 2.8973),
        (-3.0718, -0.0698),
        (-2.8973, 2.8973),
        (-0.0175, 3.7525),
        (-2.8973, 2.8973),
    ]
)
JOINT_NAMES = tuple(f"panda_joint{i}" for i in range(1, 8))
FINGER_JOINT_NAMES = ("panda_finger_joint1", "panda_finger_joint2")
GRIPPER_OPEN_M = 0.04  # per finger; the gripper's command is the opening of one finger
# Hand geometry (hand frame, z along the approach, metres): palm box, finger boxes on slides.
PALM_HALF_SIZE_M = (0.02, 0.1, 0.025)
PALM_CENTRE_Z_M = 0.03
FINGER_BASE_Z_M = 0.0584
FINGER_HALF_SIZE_M = (0.01, 0.006, 0.026)
FINGER_INSET_M = 0.007  # finger centre from the hand's axis, gripper closed
FINGERTIP_Z_M = FINGER_BASE_Z_M + 2 * FINGER_HALF_SIZE_M[2]
# Between the open fingers' inner faces, from fingertip to palm, TCP above the fingertips.
FINGER_GAP_OPEN_M = 2 * (FINGER_INSET_M + GRIPPER_OPEN_M - FINGER_HALF_SIZE_M[1])
FINGERTIP_TO_PALM_M = FINGERTIP_Z_M - (PALM_CENTRE_Z_M + PALM_HALF_SIZE_M[2])
TCP_ABOVE_FINGERTIP_M = FINGERTIP_Z_M - TCP_OFFSET_M
HOME_Q = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])
LINK_MASS_KG = (4.97, 0.65, 3.23, 3.59, 1.23, 1.67, 0.74)
JOINT_KP = (4500.0, 4500.0, 3500.0, 3500.0, 2000.0, 2000.0, 2000.0)
JOINT_FORCE_LIMIT_NM = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)
ACTUATOR_NAMES = tuple(f"panda_act{i}" for i in range(1, 8)) + ("panda_gripper",)
HAND_NAME = "panda_hand"
TCP_SITE = "panda_tcp"
ROBOT_CONTYPE, ROBOT_CONAFFINITY = 2, 1  # touches the world, never itself


def _rot_x(alpha: float) -> np.ndarray:
    c, s = np.cos(alpha), np.sin(alpha)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _quat(rotation: np.ndarray) -> list[float]:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, rotation.reshape(9))
    return q.tolist()


def dh_link_transform(a: float, d: float, alpha: float, q: float) -> np.ndarray:
    c, s = np.cos(q), np.sin(q)
    rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    T = np.eye(4)
    T[:3, :3] = _rot_x(alpha) @ rz
    T[:3, 3] = np.array([a, 0, 0]) + _rot_x(alpha) @ np.array([0, 0, d])
    return T


def forward_kinematics(q: np.ndarray, T_world_base: np.ndarray | None = None) -> np.ndarray:
    """Pose of the TCP (between the fingertips, z along the approach) in the world, 4x4."""
    T = np.eye(4) if T_world_base is None else np.array(T_world_base, dtype=np.float64)
    for (a, d, alpha), qi in zip(PANDA_DH, q, strict=True):
        T = T @ dh_link_transform(a, d, alpha, qi)
    flange = dh_link_transform(0.0, FLANGE_D_M + TCP_OFFSET_M, 0.0, -np.pi / 4)
    return T @ flange


def _capsule(body, start, end, radius: float, mass: float, rgba):
    start, end = np.asarray(start, dtype=np.float64), np.asarray(end, dtype=np.float64)
    if np.linalg.norm(end - start) < 1e-4:
        end = start + np.array([0.0, 0.0, 1e-3])
    body.add_geom(
        type=mujoco.mjtGeom.mjGEOM_CAPSULE,
        fromto=np.concatenate([start, end]).tolist(),
        size=[radius, 0, 0],
        mass=mass,
        rgba=rgba,
        contype=ROBOT_CONTYPE,
        conaffinity=ROBOT_CONAFFINITY,
    )


def add_panda(spec: mujoco.MjSpec, base_pos, base_yaw: float = 0.0, rgba=(0.92, 0.92, 0.95, 1.0)) -> None:
    """Add the arm, gripper, actuators and TCP site to spec's world body."""
    rgba = list(rgba)
    c, s = np.cos(base_yaw / 2), np.sin(base_yaw / 2)
    base = spec.worldbody.add_body(name="panda_link0", pos=list(base_pos), quat=[c, 0, 0, s])
    _capsule(base, [0, 0, 0.0], [0, 0, 0.12], 0.07, 3.0, rgba)
    parent = base
    offsets = [np.array([a, 0, 0]) + _rot_x(alpha) @ np.array([0, 0, d]) for a, d, alpha in PANDA_DH]
    for i, (_, _, alpha) in enumerate(PANDA_DH):
        body = parent.add_body(name=f"panda_link{i + 1}", pos=offsets[i].tolist(), quat=_quat(_rot_x(alpha)))
        body.gravcomp = 1.0
        lo, hi = JOINT_LIMITS[i]
        body.add_joint(
            name=JOINT_NAMES[i],
            type=mujoco.mjtJoint.mjJNT_HINGE,
            axis=[0, 0, 1],
            range=[lo, hi],
            damping=10.0,
            armature=0.1,
        )
        if i + 1 < len(PANDA_DH):
            a_next, d_next, alpha_next = PANDA_DH[i + 1]
            child = np.array([a_next, 0, 0]) + _rot_x(alpha_next) @ np.array([0, 0, d_next])
        else:
            child = np.array([0.0, 0.0, FLANGE_D_M])
        _capsule(body, [0, 0, 0], child, 0.055 if i < 4 else 0.045, LINK_MASS_KG[i], rgba)
        parent = body
    c, s = np.cos(-np.pi / 8), np.sin(-np.pi / 8)
    hand = parent.add_body(name=HAND_NAME, pos=[0, 0, FLANGE_D_M], quat=[c, 0, 0, s])
    hand.gravcomp = 1.0
    hand.add_geom(
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=list(PALM_HALF_SIZE_M),
        pos=[0, 0, PALM_CENTRE_Z_M],
        mass=0.73,
        rgba=rgba,
        contype=ROBOT_CONTYPE,
        conaffinity=ROBOT_CONAFFINITY,
    )
    hand.add_site(name=TCP_SITE, pos=[0, 0, TCP_OFFSET_M], size=[0.005, 0, 0])
    for k, sign in enumerate((1.0, -1.0)):
        finger = hand.add_body(name=f"panda_finger{k + 1}", pos=[0, 0, FINGER_BASE_Z_M])
        finger.gravcomp = 1.0
        finger.add_joint(
            name=FINGER_JOINT_NAMES[k],
            type=mujoco.mjtJoint.mjJNT_SLIDE,
            axis=[0, sign, 0],
            range=[0.0, GRIPPER_OPEN_M],
            damping=5.0,
            armature=0.05,
        )
        finger.add_geom(
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=list(FINGER_HALF_SIZE_M),
            pos=[0, sign * FINGER_INSET_M, FINGER_HALF_SIZE_M[2]],
            mass=0.02,
            rgba=[0.2, 0.2, 0.2, 1],
            friction=[1.5, 0.02, 0.002],
            condim=4,
            contype=ROBOT_CONTYPE,
            conaffinity=ROBOT_CONAFFINITY,
        )
    spec.add_equality(  # a stiff coupling keeps the fingers symmetric under grasp loads
        type=mujoco.mjtEq.mjEQ_JOINT,
        name1=FINGER_JOINT_NAMES[0],
        name2=FINGER_JOINT_NAMES[1],
        data=[0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
        solref=[0.005, 1.0],
        solimp=[0.95, 0.99, 0.001, 0.5, 2.0],
    )
    for i, name in enumerate(JOINT_NAMES):
        kp = JOINT_KP[i]
        spec.add_actuator(
            name=ACTUATOR_NAMES[i],
            target=name,
            trntype=mujoco.mjtTrn.mjTRN_JOINT,
            gaintype=mujoco.mjtGain.mjGAIN_FIXED,
            gainprm=[kp] + [0] * 9,
            biastype=mujoco.mjtBias.mjBIAS_AFFINE,
            biasprm=[0, -kp, -0.1 * kp] + [0] * 7,
            ctrllimited=True,
            ctrlrange=list(JOINT_LIMITS[i]),
            forcelimited=True,
            forcerange=[-JOINT_FORCE_LIMIT_NM[i], JOINT_FORCE_LIMIT_NM[i]],
        )
    spec.add_actuator(
        name=ACTUATOR_NAMES[-1],
        target=FINGER_JOINT_NAMES[0],
        trntype=mujoco.mjtTrn.mjTRN_JOINT,
        gaintype=mujoco.mjtGain.mjGAIN_FIXED,
        gainprm=[2000.0] + [0] * 9,
        biastype=mujoco.mjtBias.mjBIAS_AFFINE,
        biasprm=[0, -2000.0, -100.0] + [0] * 7,
        ctrllimited=True,
        ctrlrange=[0.0, GRIPPER_OPEN_M],
        forcelimited=True,
        forcerange=[-70.0, 70.0],
    )
