"""Batched forward kinematics of one body (or a point on it) from rollout states.

MuJoCo's rollout returns only states; the rewards need the hand pose at every control step of every
sampled path. This evaluates the serial chain world -> body with numpy for a whole batch of qpos at
once (hinge, slide and free joints; the same conventions as mj_kinematics, including qpos0).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np


def quat_to_matrix(quat_wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrices [..., 3, 3] from unit quaternions [..., 4] in MuJoCo's (w, x, y, z) order."""
    q = np.asarray(quat_wxyz, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


_EYE = np.eye(3)


@dataclass(frozen=True)
class _Joint:
    kind: int
    qpos_adr: int
    axis: np.ndarray
    anchor: np.ndarray
    qpos0: np.ndarray

    @property
    def skew(self) -> np.ndarray:
        a = self.axis / np.linalg.norm(self.axis)
        return np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])


@dataclass(frozen=True)
class _Link:
    pos: np.ndarray
    rot: np.ndarray
    joints: tuple[_Joint, ...]


class BodyKinematics:
    """World pose of a point rigidly attached to one body, for batches of qpos vectors."""

    def __init__(self, model: mujoco.MjModel, body: str | int, point_in_body: np.ndarray | None = None):
        body_id = body if isinstance(body, int) else mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)
        if body_id < 0:
            raise ValueError(f"body {body!r} not in the model")
        chain = []
        b = body_id
        while b != 0:
            chain.append(b)
            b = int(model.body_parentid[b])
        links = []
        for b in reversed(chain):
            joints = []
            for j in range(model.body_jntadr[b], model.body_jntadr[b] + model.body_jntnum[b]):
                kind = int(model.jnt_type[j])
                if kind == mujoco.mjtJoint.mjJNT_BALL:
                    raise ValueError("ball joints are not supported in the kinematic chain")
                adr = int(model.jnt_qposadr[j])
                width = 7 if kind == mujoco.mjtJoint.mjJNT_FREE else 1
                joints.append(
                    _Joint(
                        kind,
                        adr,
                        model.jnt_axis[j].copy(),
                        model.jnt_pos[j].copy(),
                        model.qpos0[adr : adr + width].copy(),
                    )
                )
            links.append(_Link(model.body_pos[b].copy(), quat_to_matrix(model.body_quat[b]), tuple(joints)))
        self._links = tuple(links)
        self._skews = {id(j): (j.skew, j.skew @ j.skew) for link in links for j in link.joints}
        self._point = np.zeros(3) if point_in_body is None else np.asarray(point_in_body, dtype=np.float64)
        self.body_id = body_id

    def __call__(self, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """qpos [..., nq] -> (point position [..., 3], body rotation [..., 3, 3]) in the world frame."""
        qpos = np.asarray(qpos, dtype=np.float64)
        batch = qpos.shape[:-1]
        pos = np.zeros(batch + (3,))
        rot = np.broadcast_to(np.eye(3), batch + (3, 3)).copy()
        for link in self._links:
            pos = pos + rot @ link.pos
            rot = rot @ link.rot
            for joint in link.joints:
                if joint.kind == mujoco.mjtJoint.mjJNT_FREE:
                    pos = qpos[..., joint.qpos_adr : joint.qpos_adr + 3].copy()
                    rot = quat_to_matrix(qpos[..., joint.qpos_adr + 3 : joint.qpos_adr + 7])
                elif joint.kind == mujoco.mjtJoint.mjJNT_SLIDE:
                    offset = qpos[..., joint.qpos_adr] - joint.qpos0[0]
                    pos = pos + (rot @ joint.axis) * offset[..., None]
                else:
                    angle = qpos[..., joint.qpos_adr] - joint.qpos0[0]
                    k, k2 = self._skews[id(joint)]
                    r_joint = _EYE + np.sin(angle)[..., None, None] * k + (1 - np.cos(angle))[..., None, None] * k2
                    anchor_world = pos + rot @ joint.anchor
                    rot = rot @ r_joint
                    pos = anchor_world - rot @ joint.anchor
        return pos + rot @ self._point, rot
