"""The visible part of a reconstructed surface placed on the observed depth.

A marching-cubes surface of a 32^3 grid is off the object by up to half a voxel (6-21 mm here),
also where the camera saw the object at millimetre precision. Each mesh vertex that faces the camera
and projects into the object's own mask is moved along its camera ray to the depth observed there
(smoothed over the mask), when that is at most `max_shift_m` away; the shifts are then spread over a
few rings of neighbouring vertices, fading, so the unseen part joins the seen part without a step.
Vertices on the table plane keep their height (the base stays flat). The faces are unchanged, so a
closed mesh stays closed.
"""

from dataclasses import dataclass

import numpy as np
import scipy.sparse
import trimesh

from arm_core.camera import pixel_coordinates, transform_points

from .object_depth import object_depth_average


@dataclass(frozen=True)
class SnapSettings:
    """max_shift_voxels: largest move along the ray, in voxels of the object's grid; min_facing_cos:
    cosine between a vertex normal and the direction to the camera below which a vertex is not
    moved (grazing surfaces, silhouette rims); smoothing_px: side of the box filter the observed depth
    is averaged over inside the mask; spread_rings: rings of neighbours the shifts fade over;
    mask_erosion_px: mask pixels this close to its border (flying pixels, misregistration) are not used."""

    max_shift_voxels: float = 1.0
    min_facing_cos: float = 0.3
    smoothing_px: int = 5
    spread_rings: int = 3
    mask_erosion_px: int = 2


def smoothed_object_depth(depth_m: np.ndarray, labels: np.ndarray, object_ids, settings: SnapSettings) -> np.ndarray:
    """Each object's depth (metres) averaged over a smoothing_px box within its own eroded mask, all
    in one image; 0 where no object's eroded mask is or the pixel has no return."""
    return object_depth_average(depth_m, labels, object_ids, settings.smoothing_px, settings.mask_erosion_px)


def vertex_adjacency(mesh: trimesh.Trimesh) -> scipy.sparse.csr_matrix:
    """Row-normalised vertex adjacency (mean over a vertex's neighbours)."""
    edges = np.asarray(mesh.edges_unique)
    n = len(mesh.vertices)
    ones = np.ones(2 * len(edges))
    adjacency = scipy.sparse.coo_matrix(
        (ones, (np.concatenate([edges[:, 0], edges[:, 1]]), np.concatenate([edges[:, 1], edges[:, 0]]))), (n, n)
    ).tocsr()
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    return scipy.sparse.diags(1.0 / np.maximum(degree, 1.0)) @ adjacency


def bilinear_own_depth(object_depth_m, labels, object_id: int, u, v, valid) -> np.ndarray:
    """Depth at continuous pixel coordinates (u, v) (pixel centres at integers, as back-projection
    has them), bilinear over the four pixels around; 0 unless all four carry object_id and a depth."""
    height, width = object_depth_m.shape
    u0 = np.floor(np.where(valid, u, -2.0)).astype(np.int64)
    v0 = np.floor(np.where(valid, v, -2.0)).astype(np.int64)
    inside = valid & (u0 >= 0) & (u0 + 1 < width) & (v0 >= 0) & (v0 + 1 < height)
    u0, v0 = np.where(inside, u0, 0), np.where(inside, v0, 0)
    fu, fv = np.where(inside, u - u0, 0.0), np.where(inside, v - v0, 0.0)
    corners = [
        (v0, u0, (1 - fu) * (1 - fv)),
        (v0, u0 + 1, fu * (1 - fv)),
        (v0 + 1, u0, (1 - fu) * fv),
        (v0 + 1, u0 + 1, fu * fv),
    ]
    labels = np.asarray(labels)
    depth = np.zeros(len(u0))
    for rows, cols, weight in corners:
        value = object_depth_m[rows, cols]
        inside &= (labels[rows, cols] == object_id) & (value > 0)
        depth += weight * value
    return np.where(inside, depth, 0.0)


def snap_to_observed_depth(
    mesh_world: trimesh.Trimesh,
    object_depth_m: np.ndarray,
    labels: np.ndarray,
    object_id: int,
    K: np.ndarray,
    T_world_camera: np.ndarray,
    max_shift_m: float,
    table_height_m: float,
    settings: SnapSettings = SnapSettings(),
) -> tuple[trimesh.Trimesh, int]:
    """-> (mesh with its seen vertices on the observed surface, number of vertices snapped).
    object_depth_m: smoothed_object_depth of the frame; only pixels labelled object_id are used."""
    if len(mesh_world.faces) == 0:
        return mesh_world, 0
    vertices = np.asarray(mesh_world.vertices, dtype=np.float64)
    normals = np.asarray(mesh_world.vertex_normals, dtype=np.float64)
    T_camera_world = np.linalg.inv(T_world_camera)
    points_camera = transform_points(vertices, T_camera_world)
    z = points_camera[:, 2]
    in_front = z > 1e-3
    u, v = pixel_coordinates(np.where(in_front[:, None], points_camera, 1.0), K)
    height, width = object_depth_m.shape
    observed = bilinear_own_depth(object_depth_m, labels, object_id, u, v, in_front)
    to_camera = np.asarray(T_world_camera)[:3, 3] - vertices
    to_camera /= np.maximum(np.linalg.norm(to_camera, axis=1, keepdims=True), 1e-12)
    facing = np.einsum("ij,ij->i", normals, to_camera) > settings.min_facing_cos
    scale = np.where(observed > 0, observed / np.maximum(z, 1e-9), 1.0)
    shift_camera = points_camera * (scale - 1.0)[:, None]
    snapped = facing & (observed > 0) & (np.linalg.norm(shift_camera, axis=1) <= max_shift_m)
    if not snapped.any():
        return mesh_world, 0
    shift = np.where(snapped[:, None], shift_camera @ np.asarray(T_world_camera)[:3, :3].T, 0.0)
    mean_of_neighbours = vertex_adjacency(mesh_world)
    fixed = snapped.copy()
    for _ in range(settings.spread_rings):
        spread = 0.5 * (mean_of_neighbours @ shift)
        reached = (mean_of_neighbours @ fixed.astype(np.float64)) > 0
        shift = np.where(fixed[:, None], shift, np.where(reached[:, None], spread, 0.0))
        fixed |= reached
    on_table = vertices[:, 2] <= table_height_m + 1e-6
    shift[on_table, 2] = 0.0
    moved = trimesh.Trimesh(vertices + shift, np.asarray(mesh_world.faces), process=False)
    return moved, int(snapped.sum())
