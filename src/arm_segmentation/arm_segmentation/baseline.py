"""Classic baseline: RANSAC table plane, then DBSCAN Euclidean clustering of the points above it.

Uses no gravity prior and no colour: the textbook tabletop pipeline (plane model, polygonal prism
above the plane's convex hull, density-based clustering) that the default method is compared to.
"""

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, QhullError, cKDTree

from arm_core.camera import backproject_image
from arm_core.frames import validate_frame


@dataclass(frozen=True)
class BaselineParams:
    """RANSAC and DBSCAN parameters (metres)."""

    ransac_iterations: int = 300
    ransac_sample: int = 6000
    plane_threshold_m: float = 0.01
    max_object_height_m: float = 0.6
    voxel_m: float = 0.005
    eps_m: float = 0.012
    min_samples: int = 8
    min_cluster_points: int = 30
    max_instances: int = 255


def ransac_plane(points: np.ndarray, rng: np.random.Generator, params: BaselineParams):
    """Dominant plane (unit normal n towards the camera, offset d: n.p + d = 0) of (N, 3) points."""
    if len(points) < 3:
        return None
    sample = points[rng.choice(len(points), min(len(points), params.ransac_sample), replace=False)]
    idx = rng.integers(0, len(sample), size=(params.ransac_iterations, 3))
    a, b, c = sample[idx[:, 0]], sample[idx[:, 1]], sample[idx[:, 2]]
    normals = np.cross(b - a, c - a)
    norm = np.linalg.norm(normals, axis=1)
    ok = norm > 1e-9
    if not np.any(ok):
        return None
    normals = normals[ok] / norm[ok, None]
    offsets = -np.einsum("ij,ij->i", normals, a[ok])
    inliers = np.abs(sample @ normals.T + offsets) < params.plane_threshold_m
    best = int(np.argmax(inliers.sum(axis=0)))
    n, d = normals[best], offsets[best]
    support = points[np.abs(points @ n + d) < params.plane_threshold_m]
    if len(support) >= 3:
        centre = support.mean(axis=0)
        n = np.linalg.svd(support - centre, full_matrices=False)[2][2]
        d = -float(n @ centre)
    if d < 0:  # the camera (origin) must be on the positive side
        n, d = -n, -d
    return n, d


def dbscan(points: np.ndarray, eps: float, min_samples: int) -> np.ndarray:
    """DBSCAN labels (N,) int64, -1 = noise; neighbourhoods include the point itself."""
    n = len(points)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    pairs = cKDTree(points).query_pairs(eps, output_type="ndarray")
    counts = np.bincount(pairs.ravel(), minlength=n) + 1
    core = counts >= min_samples
    labels = np.full(n, -1, dtype=np.int64)
    if not np.any(core):
        return labels
    core_pairs = pairs[core[pairs[:, 0]] & core[pairs[:, 1]]]
    graph = coo_matrix((np.ones(len(core_pairs)), (core_pairs[:, 0], core_pairs[:, 1])), shape=(n, n))
    _, component = connected_components(graph, directed=False)
    labels[core] = component[core]
    border = pairs[core[pairs[:, 0]] ^ core[pairs[:, 1]]]
    core_end = np.where(core[border[:, 0]], border[:, 0], border[:, 1])
    other_end = np.where(core[border[:, 0]], border[:, 1], border[:, 0])
    labels[other_end] = labels[core_end]
    return labels


def segment_baseline(rgb, depth_m, K, T_world_camera, params: BaselineParams | None = None, seed: int = 0):
    """RANSAC plane + DBSCAN instance labels (uint16 HxW, 0 = table / background)."""
    params = params or BaselineParams()
    frame = validate_frame(depth_m, K, T_world_camera, rgb=rgb)
    depth, K = frame.depth_m, frame.K
    labels = np.zeros(depth.shape, dtype=np.uint16)
    valid = depth > 0
    points = backproject_image(depth, K)[valid].astype(np.float64)
    plane = ransac_plane(points, np.random.default_rng(seed), params)
    if plane is None:
        return labels
    n, d = plane
    height = points @ n + d
    u = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    plane_uv = np.stack([points @ u, points @ v], axis=1)
    table = np.abs(height) < params.plane_threshold_m
    try:
        hull = ConvexHull(plane_uv[table][:: max(1, int(table.sum()) // 4000)])
    except (QhullError, ValueError):
        return labels
    inside = np.all(plane_uv @ hull.equations[:, :2].T + hull.equations[:, 2] <= 0, axis=1)
    above = inside & (height >= params.plane_threshold_m) & (height <= params.max_object_height_m)
    if not np.any(above):
        return labels
    above_points = points[above]
    keys = np.floor(above_points / params.voxel_m).astype(np.int64)
    keys -= keys.min(axis=0)
    dims = keys.max(axis=0) + 1
    flat = (keys[:, 0] * dims[1] + keys[:, 1]) * dims[2] + keys[:, 2]
    unique_keys, voxel_of_point = np.unique(flat, return_inverse=True)
    voxel_count = np.bincount(voxel_of_point, minlength=len(unique_keys))
    voxel_points = (
        np.stack(
            [np.bincount(voxel_of_point, weights=above_points[:, k], minlength=len(unique_keys)) for k in range(3)],
            axis=1,
        )
        / voxel_count[:, None]
    )
    cluster = dbscan(voxel_points, params.eps_m, params.min_samples)
    point_cluster = cluster[voxel_of_point]
    sizes = np.bincount(point_cluster[point_cluster >= 0])
    keep = np.flatnonzero(sizes >= params.min_cluster_points)
    keep = keep[np.argsort(-sizes[keep], kind="stable")][: params.max_instances]
    remap = np.zeros(len(sizes) + 1, dtype=np.uint16)
    remap[keep + 1] = np.arange(1, len(keep) + 1, dtype=np.uint16)
    pixel_labels = np.zeros(int(valid.sum()), dtype=np.uint16)
    pixel_labels[above] = remap[point_cluster + 1]
    labels[valid] = pixel_labels
    return labels
