"""Object poses from re-observation: each object's own mesh fitted to a new depth frame (no rclpy).

The closed loop of the manipulation benchmark can observe the objects the way a robot would: a new
RGB-D frame from the same camera, the pixels of each object (its instance mask), and the object's
mesh (the method's reconstruction, not the true shape) moved onto those points by point-to-plane ICP,
starting from where the twin predicts it is. An object with too few points in view (hidden, or behind
the hand) keeps the twin's prediction.
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
    steps; max_distance_m: correspondences further apart are ignored; max_shift_m: a fit that moves
    the object further than this from the prediction is refused (a wrong match, not a motion)."""

    model_points: int = 1500
    max_points: int = 400
    min_points: int = 30
    iterations: int = 8
    max_distance_m: float = 0.015
    max_shift_m: float = 0.05


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


class DepthTracker:
    """Fits each object's mesh (object frame, metres) to its observed points (world frame)."""

    def __init__(self, meshes: dict[int, trimesh.Trimesh], params: DepthTrackingParams | None = None, seed: int = 0):
        self.params = params or DepthTrackingParams()
        self.rng = np.random.default_rng(seed)
        self.models: dict[int, tuple[cKDTree, np.ndarray, np.ndarray]] = {}
        for object_id, mesh in meshes.items():
            if mesh is None or len(mesh.faces) == 0:
                continue
            points, faces = trimesh.sample.sample_surface_even(mesh, self.params.model_points, seed=seed)
            if len(points) == 0:
                continue
            normals = mesh.face_normals[faces]
            self.models[object_id] = (cKDTree(points), np.asarray(points), np.asarray(normals))

    def fit(self, object_id: int, points_world: np.ndarray, T_world_object: np.ndarray) -> np.ndarray | None:
        """The object's pose (4x4) with its mesh on points_world (N, 3), from T_world_object; None when
        it has no model, too few points or the fit moves it by more than max_shift_m."""
        p = self.params
        if object_id not in self.models or len(points_world) < p.min_points:
            return None
        if len(points_world) > p.max_points:
            points_world = points_world[self.rng.choice(len(points_world), p.max_points, replace=False)]
        tree, model_points, model_normals = self.models[object_id]
        T = np.asarray(T_world_object, dtype=np.float64).copy()
        for _ in range(p.iterations):
            local = (points_world - T[:3, 3]) @ T[:3, :3]
            distance, index = tree.query(local, distance_upper_bound=p.max_distance_m)
            close = np.isfinite(distance)
            if close.sum() < p.min_points:
                return None
            src, q, n = local[close], model_points[index[close]], model_normals[index[close]]
            A = np.concatenate([np.cross(src, n), n], axis=1)
            b = -np.einsum("ij,ij->i", src - q, n)
            x, *_ = np.linalg.lstsq(A, b, rcond=None)
            # The points move by delta in the object frame: T^-1 becomes delta T^-1.
            T = T @ np.linalg.inv(_small_motion(x[:3], x[3:]))
            if np.linalg.norm(x) < 1e-5:
                break
        if np.linalg.norm(T[:3, 3] - T_world_object[:3, 3]) > p.max_shift_m:
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
        bounds = np.searchsorted(ids, list(predicted), side="left"), np.searchsorted(ids, list(predicted), side="right")
        fitted = {}
        for object_id, start, stop in zip(predicted, *bounds, strict=True):
            points = backproject_pixels(depth_m, v[start:stop], u[start:stop], K, T_world_camera)
            pose = self.fit(object_id, points, predicted[object_id])
            if pose is not None:
                fitted[object_id] = pose
        return fitted
