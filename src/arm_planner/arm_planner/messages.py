"""ROS messages <-> planner objects (message classes only, no rclpy)."""

from __future__ import annotations

import numpy as np
import trimesh
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from arm_interfaces.action import Manipulate
from arm_planner.tasks import TASK_GRASP, TASK_PUSH, TASK_REARRANGE
from arm_planner.twin import TwinObject
from arm_ros.conversions import ConversionError
from arm_ros.conversions.meshes import msg_to_mesh
from arm_ros.conversions.poses import pose_to_matrix
from arm_ros.conversions.stamps import seconds_to_duration

TASK_NAMES = {
    Manipulate.Goal.TASK_GRASP: TASK_GRASP,
    Manipulate.Goal.TASK_PUSH: TASK_PUSH,
    Manipulate.Goal.TASK_REARRANGE: TASK_REARRANGE,
}


DEFAULT_MAX_OBJECT_SIZE_M = 1.0


def object_size_m(mesh: trimesh.Trimesh | None, parts: list[trimesh.Trimesh]) -> float:
    """Largest side of the axis-aligned box around an object's mesh and parts, m (object frame)."""
    vertices = [m.vertices for m in ([mesh] if mesh is not None else []) + parts if len(m.vertices)]
    if not vertices:
        return 0.0
    stacked = np.concatenate(vertices)
    return float(np.max(stacked.max(axis=0) - stacked.min(axis=0)))


def twin_objects_from_msg(
    msg, max_object_size_m: float = DEFAULT_MAX_OBJECT_SIZE_M
) -> tuple[list[TwinObject], float, dict[int, str]]:
    """ReconstructedObjectArray -> (objects, table height m, {id: why it was dropped}).

    Malformed objects (bad mesh indices, non-finite poses, larger than `max_object_size_m`) are dropped
    with a reason instead of failing the whole array; an object whose parts are empty keeps its mesh
    for the twin to decompose.
    """
    table_height_m = float(msg.table_height_m)
    if not np.isfinite(table_height_m):
        raise ConversionError("table_height_m is not finite")
    objects, dropped = [], {}
    for obj in msg.objects:
        object_id = int(obj.id)
        try:
            T = pose_to_matrix(obj.pose)
            if not np.all(np.isfinite(T)):
                raise ConversionError("pose is not finite")
            vertices, faces = msg_to_mesh(obj.mesh)
            mesh = trimesh.Trimesh(vertices, faces, process=False) if len(faces) else None
            parts = []
            for part in obj.convex_parts:
                part_vertices, part_faces = msg_to_mesh(part)
                if len(part_vertices):
                    parts.append(trimesh.Trimesh(part_vertices, part_faces, process=False))
        except (ConversionError, ValueError, IndexError) as exc:
            dropped[object_id] = f"malformed object: {exc}"
            continue
        if mesh is None and not parts:
            dropped[object_id] = "empty mesh and no convex parts"
            continue
        size_m = object_size_m(mesh, parts)
        if size_m > max_object_size_m:
            dropped[object_id] = f"{size_m:.3g} m across, larger than max_object_size_m = {max_object_size_m} m"
            continue
        objects.append(TwinObject(object_id, T, mesh, parts, float(obj.visible_fraction), obj.method))
    return objects, table_height_m, dropped


def trajectory_msg(joint_names, times_s: np.ndarray, positions: np.ndarray, header=None) -> JointTrajectory:
    """Waypoints (times from start, s; positions [N, len(joint_names)]) -> JointTrajectory."""
    msg = JointTrajectory()
    if header is not None:
        msg.header = header
    msg.joint_names = list(joint_names)
    for t, q in zip(np.asarray(times_s, dtype=np.float64), np.asarray(positions, dtype=np.float64), strict=True):
        point = JointTrajectoryPoint(positions=q.tolist(), time_from_start=seconds_to_duration(float(t)))
        msg.points.append(point)
    return msg


def joint_state_arrays(msg, arm_joints, finger_joint: str) -> tuple[np.ndarray, float]:
    """JointState -> (arm joint angles in `arm_joints` order, finger opening m). Raises ConversionError."""
    names = list(msg.name)
    positions = np.asarray(msg.position, dtype=np.float64)
    if len(positions) != len(names):
        raise ConversionError(f"joint_states has {len(names)} names but {len(positions)} positions")
    index = {n: i for i, n in enumerate(names)}
    missing = [n for n in (*arm_joints, finger_joint) if n not in index]
    if missing:
        raise ConversionError(f"joint_states lacks {missing}")
    arm_q = positions[[index[n] for n in arm_joints]]
    opening = float(positions[index[finger_joint]])
    if not (np.all(np.isfinite(arm_q)) and np.isfinite(opening)):
        raise ConversionError("joint_states holds non-finite positions")
    return arm_q, opening
