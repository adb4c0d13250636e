"""shape_msgs/Mesh and arm_interfaces/ReconstructedObject <-> numpy meshes."""

import numpy as np
from shape_msgs.msg import Mesh

from arm_interfaces.msg import ReconstructedObject
from arm_ros.conversions import ConversionError
from arm_ros.conversions.poses import matrix_to_pose, pose_to_matrix
from arm_ros.conversions.sequences import (
    array_from_points,
    array_from_triangles,
    points_from_array,
    triangles_from_array,
)


def mesh_to_msg(vertices: np.ndarray, faces: np.ndarray) -> Mesh:
    """(N,3) vertices in metres and (M,3) triangle indices -> shape_msgs/Mesh."""
    msg = Mesh()
    msg.vertices = points_from_array(vertices)
    msg.triangles = triangles_from_array(faces)
    return msg


def msg_to_mesh(msg: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """shape_msgs/Mesh -> ((N,3) float64 vertices, (M,3) int64 faces). Raises on bad indices."""
    vertices = array_from_points(msg.vertices)
    faces = array_from_triangles(msg.triangles)
    if not np.all(np.isfinite(vertices)):
        raise ConversionError("mesh has non-finite vertices")
    if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise ConversionError("mesh triangle indices out of range")
    return vertices, faces


def _as_vf(mesh) -> tuple[np.ndarray, np.ndarray]:
    return (np.asarray(mesh.vertices), np.asarray(mesh.faces)) if hasattr(mesh, "vertices") else mesh


def object_msg(
    object_id: int,
    T_world_object,
    mesh_local,
    convex_parts_local=(),
    visible_fraction: float = -1.0,
    method: str = "",
    grid=None,
) -> ReconstructedObject:
    """Object-frame meshes (trimesh or (V, F)) + T_world_object -> arm_interfaces/ReconstructedObject."""
    msg = ReconstructedObject(id=int(object_id), visible_fraction=float(visible_fraction), method=method)
    msg.pose = matrix_to_pose(T_world_object)
    msg.mesh = mesh_to_msg(*_as_vf(mesh_local))
    msg.convex_parts = [mesh_to_msg(*_as_vf(p)) for p in convex_parts_local]
    if grid is not None:
        msg.grid = grid
    return msg


def reconstructed_object_msg(
    object_id: int, mesh_world, convex_parts_world=(), visible_fraction: float = -1.0, method: str = "", grid=None
) -> ReconstructedObject:
    """World-frame meshes -> ReconstructedObject whose object frame is parallel to the world frame with its
    origin at the mesh's vertex centroid (see the message definition)."""
    vertices, faces = _as_vf(mesh_world)
    T = np.eye(4)
    T[:3, 3] = np.asarray(vertices, dtype=np.float64).mean(axis=0) if len(vertices) else 0.0
    parts = [(np.asarray(v) - T[:3, 3], f) for v, f in map(_as_vf, convex_parts_world)]
    return object_msg(object_id, T, (np.asarray(vertices) - T[:3, 3], faces), parts, visible_fraction, method, grid)


def reconstructed_object_from_msg(msg: ReconstructedObject) -> tuple[np.ndarray, tuple, list]:
    """arm_interfaces/ReconstructedObject -> (T_world_object, (V, F) mesh, [(V, F)] convex parts), object
    frame. Raises ConversionError on a non-finite pose or a malformed mesh."""
    T = pose_to_matrix(msg.pose)
    return T, msg_to_mesh(msg.mesh), [msg_to_mesh(p) for p in msg.convex_parts]
