"""Object poses from re-observation: each object's own mesh fitted to a new depth frame (no rclpy).

The closed loop of the manipulation benchmark can observe the objects the way a robot would: a new
RGB-D frame from the same camera, the pixels of each object (its instance mask), and the object's
mesh (the method's reconstruction, not the true shape) moved onto those points by point-to-plane ICP,
starting from where the twin predicts it is. The twin's prediction stands where the view cannot
correct it: an object with too few points in view (hidden, or behind the hand), a fit that leaves
the points off the mesh, one that would move it further than an object moves between two frames,
and one within the depth noise of the prediction (an object at rest stays put). Directions the
points do not pin down (a sliding plane, a solid of revolution's spin) are damped to no motion.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from arm_core.camera import backproject_pixels


@dataclass(frozen=True)
class DepthTrackingParams:
    """model_points: points sampled on each mesh's surface; max_points: observed points used per
    object (a random subset); min_points: fewer points in view keep the prediction; iterations: ICP
    steps; max_distance_m: correspondences further apart are ignored; damping: weight (relative to
    the number of points) that keeps unconstrained motions at zero, rotations measured at the
    mesh's radius; min_inlier_share, max_rms_m: the fitted points that must lie within
    max_distance_m of the mesh, and their largest RMS point-to-plane distance; max_shift_m,
    max_turn_rad: a fit moving the object further from the prediction is refused (a wrong match:
    0.02 m per 0.1 s frame is 0.2 m/s); min_shift_m, min_turn_rad: a fit closer to the prediction
    is depth noise and leaves it."""

    model_points: int = 1500
    max_points: int = 400
    min_points: int = 30
    iterations: int = 8
    max_distance_m: float = 0.015
    damping: float = 0.05
    min_inlier_share: float = 0.7
    max_rms_m: float = 0.004
    max_shift_m: float = 0.02
    max_turn_rad: float = 0.35
    min_shift_m: float = 0.003
    min_turn_rad: float = 0.05


def _small_motion(omega: np.ndarray, v: np.ndarray) -> np.ndarray:
    """4x4 rigid transform of rotation vector omega (rad) and translation v (m)."""
    T = np.eye(4)
    angle = float(np.linalg.norm(omega))
    if angle > 1e-12:
        axis = omega / angle
        K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
        T[:3, :3] = np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)
    T[:3, 3] = v
    return T


def rotation_vector(R: np.ndarray) -> np.ndarray:
    """Axis times angle (rad, 0 to pi) of a rotation matrix."""
    angle = float(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))
    if angle < 1e-9:
        return np.zeros(3)
    if angle > np.pi - 1e-3:  # the antisymmetric part vanishes: the axis from R + I instead
        B = (R + np.eye(3)) / 2.0
        k = int(np.argmax(np.diag(B)))
        return B[:, k] / np.sqrt(max(B[k, k], 1e-12)) * angle
    axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / (2.0 * np.sin(angle))
    return axis * angle


class DepthTracker:
    """Fits each object's mesh (object frame, metres) to its observed points (world frame)."""

    def __init__(self, meshes: dict[int, trimesh.Trimesh], params: DepthTrackingParams | None = None, seed: int = 0):
        self.params = params or DepthTrackingParams()
        self.rng = np.random.default_rng(seed)
        self.models: dict[int, tuple[cKDTree, np.ndarray, np.ndarray, float]] = {}
        for object_id, mesh in meshes.items():
            if mesh is None or len(mesh.faces) == 0:
                continue
            points, faces = trimesh.sample.sample_surface_even(mesh, self.params.model_points, seed=seed)
            if len(points) == 0:
                continue
            normals = mesh.face_normals[faces]
            radius_m = max(float(np.linalg.norm(points - points.mean(axis=0), axis=1).max()), 1e-3)
            self.models[object_id] = (cKDTree(points), np.asarray(points), np.asarray(normals), radius_m)

    def fit(self, object_id: int, points_world: np.ndarray, T_world_object: np.ndarray) -> np.ndarray | None:
        """The object's pose (4x4) with its mesh on points_world (N, 3), from T_world_object; None when
        the prediction stands (see the module docstring)."""
        p = self.params
        if object_id not in self.models or len(points_world) < p.min_points:
            return None
        if len(points_world) > p.max_points:
            points_world = points_world[self.rng.choice(len(points_world), p.max_points, replace=False)]
        tree, model_points, model_normals, radius_m = self.models[object_id]
        T_start = np.asarray(T_world_object, dtype=np.float64)
        T = T_start.copy()
        scale = np.array([radius_m] * 3 + [1.0] * 3)
        for _ in range(p.iterations):
            local = (points_world - T[:3, 3]) @ T[:3, :3]
            distance, index = tree.query(local, distance_upper_bound=p.max_distance_m)
            close = np.isfinite(distance)
            if close.sum() < p.min_points:
                return None
            src, q, n = local[close], model_points[index[close]], model_normals[index[close]]
            A = np.concatenate([np.cross(src, n), n], axis=1) / scale  # rotations at the mesh's radius
            b = -np.einsum("ij,ij->i", src - q, n)
            x = np.linalg.solve(A.T @ A + p.damping * len(b) * np.eye(6), A.T @ b) / scale
            # The points move by delta in the object frame: T^-1 becomes delta T^-1.
            T = T @ np.linalg.inv(_small_motion(x[:3], x[3:]))
            if np.linalg.norm(x[3:]) < 1e-5 and np.linalg.norm(x[:3]) < 1e-4:
                break
        local = (points_world - T[:3, 3]) @ T[:3, :3]
        distance, index = tree.query(local, distance_upper_bound=p.max_distance_m)
        close = np.isfinite(distance)
        if close.mean() < p.min_inlier_share:
            return None
        off_plane = np.einsum("ij,ij->i", local[close] - model_points[index[close]], model_normals[index[close]])
        if np.sqrt(np.mean(off_plane**2)) > p.max_rms_m:
            return None
        shift = float(np.linalg.norm(T[:3, 3] - T_start[:3, 3]))
        turn = float(np.linalg.norm(rotation_vector(T[:3, :3] @ T_start[:3, :3].T)))
        if shift > p.max_shift_m or turn > p.max_turn_rad:
            return None
        if shift < p.min_shift_m and turn < p.min_turn_rad:
            return None
        return T

    def track(self, depth_m, labels, K, T_world_camera, predicted: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
        """Poses of the objects in `predicted` (id -> 4x4 world pose the twin expects) fitted to a depth
        image (metres) with its instance labels (pixel value = object id); only those that fit."""
        labels = np.asarray(labels)
        seen = labels.astype(np.int64) * (np.asarray(depth_m) > 0)
        v, u = np.nonzero(np.isin(seen, list(predicted)))
        ids = seen[v, u]
        order = np.argsort(ids, kind="stable")
        v, u, ids = v[order], u[order], ids[order]
        object_ids = np.array(list(predicted), dtype=np.int64)
        starts, stops = np.searchsorted(ids, object_ids, side="left"), np.searchsorted(ids, object_ids, side="right")
        fitted = {}
        for object_id, start, stop in zip(predicted, starts, stops, strict=True):
            points = backproject_pixels(depth_m, v[start:stop], u[start:stop], K, T_world_camera)
            pose = self.fit(object_id, points, predicted[object_id])
            if pose is not None:
                fitted[object_id] = pose
        return fitted
