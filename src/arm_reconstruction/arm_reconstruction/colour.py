"""Per-vertex colour of a reconstructed mesh from the RGB image it was reconstructed from.

A vertex the camera sees (its pixel belongs to the object and the depth there is within
VISIBLE_DEPTH_M of the vertex's) takes that pixel's colour; every other vertex, hidden behind the
object or another one, takes the mean colour of the object's pixels (a guess for the unseen side).
"""

import numpy as np

from arm_core.camera import project_points

VISIBLE_DEPTH_M = 0.01
GREY = np.array([150, 150, 150], dtype=np.uint8)


def vertex_colours(vertices_world, rgb, depth_m, labels, object_id: int, K, T_world_camera) -> np.ndarray:
    """(N, 3) uint8 RGB of mesh vertices (N, 3) in the world frame (metres)."""
    vertices_world = np.asarray(vertices_world, dtype=np.float64).reshape(-1, 3)
    own = labels == object_id
    mean = rgb[own].mean(axis=0).round().astype(np.uint8) if own.any() else GREY
    colours = np.tile(mean, (len(vertices_world), 1))
    if len(vertices_world) == 0:
        return colours
    pixels, z = project_points(vertices_world, K, T_world_camera)
    u, v = np.round(pixels[:, 0]).astype(np.int64), np.round(pixels[:, 1]).astype(np.int64)
    height, width = labels.shape
    inside = (z > 0) & (u >= 0) & (u < width) & (v >= 0) & (v < height)
    seen = np.zeros(len(vertices_world), dtype=bool)
    uu, vv = u[inside], v[inside]
    seen[inside] = own[vv, uu] & (np.abs(depth_m[vv, uu] - z[inside]) < VISIBLE_DEPTH_M)
    colours[seen] = rgb[v[seen], u[seen]]
    return colours
