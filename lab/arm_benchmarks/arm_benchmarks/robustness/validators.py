"""Validators: what a node publishes must be well formed. Each returns a list of problems."""

from __future__ import annotations

import numpy as np

from arm_ros.conversions import ConversionError
from arm_ros.conversions.images import K_from_camera_info, image_to_numpy
from arm_ros.conversions.meshes import msg_to_mesh
from arm_ros.conversions.poses import pose_to_matrix
from arm_sim import robot


def segmented_frame_problems(msg) -> list[str]:
    problems = []
    try:
        depth = image_to_numpy(msg.depth)
        labels = image_to_numpy(msg.labels)
        if msg.depth.encoding != "32FC1" or msg.labels.encoding != "16UC1":
            problems.append(f"encodings depth={msg.depth.encoding} labels={msg.labels.encoding}")
        if depth.shape != labels.shape:
            problems.append(f"depth {depth.shape} vs labels {labels.shape}")
        if msg.rgb.height and image_to_numpy(msg.rgb).shape[:2] != depth.shape:
            problems.append("rgb and depth differ in size")
        if np.any(np.isinf(depth)) or np.any(depth < 0):
            problems.append("depth has inf or negative values")
        ids = sorted(int(i) for i in np.unique(labels) if i > 0)
        if ids != [int(i) for i in msg.instance_ids]:
            problems.append(f"instance_ids {list(msg.instance_ids)} vs labels {ids}")
        K_from_camera_info(msg.camera_info)
        pose_to_matrix(msg.camera_pose)
        if not msg.world_frame_id:
            problems.append("no world_frame_id")
    except ConversionError as error:
        problems.append(str(error))
    return problems


def mesh_array_problems(msg) -> list[str]:
    problems = []
    if not np.isfinite(msg.table_height_m):
        problems.append("table_height_m not finite")
    ids = [int(o.id) for o in msg.objects]
    if ids != sorted(set(ids)):
        problems.append(f"ids not unique ascending: {ids}")
    for obj in msg.objects:
        try:
            pose_to_matrix(obj.pose)
            vertices, faces = msg_to_mesh(obj.mesh)
            if len(faces) == 0:
                problems.append(f"object {obj.id}: empty mesh")
            for part in obj.convex_parts:
                msg_to_mesh(part)
        except ConversionError as error:
            problems.append(f"object {obj.id}: {error}")
    return problems


def joint_state_problems(msg) -> list[str]:
    positions = np.asarray(msg.position, dtype=np.float64)
    problems = []
    if len(positions) != len(msg.name):
        problems.append(f"{len(msg.name)} names, {len(positions)} positions")
    if not np.all(np.isfinite(positions)):
        problems.append("non-finite positions")
    else:
        lo, hi = np.asarray(robot.JOINT_LIMITS, dtype=np.float64).reshape(-1, 2)[:7].T
        q = positions[:7]
        if len(q) == 7 and (np.any(q < lo - 0.05) or np.any(q > hi + 0.05)):
            problems.append("joint positions outside the limits")
    return problems


def trajectory_problems(msg) -> list[str]:
    times = np.array([p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in msg.points])
    positions = [np.asarray(p.positions, dtype=np.float64) for p in msg.points]
    problems = []
    if len(times) == 0:
        problems.append("no points")
    if len(times) > 1 and np.any(np.diff(times) <= 0):
        problems.append("time_from_start does not increase")
    if any(len(p) != len(msg.joint_names) or not np.all(np.isfinite(p)) for p in positions):
        problems.append("points with wrong sizes or non-finite positions")
    return problems
