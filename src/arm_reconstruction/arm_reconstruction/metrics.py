"""Reconstruction quality between two meshes in the same frame (metres).

Chamfer distance (chamfer_distance_m): N points are sampled uniformly by area on each surface
(A on mesh_a, B on mesh_b, the same seed for both, so CD(m, m) = 0 and CD is symmetric); with
d(p, Q) the Euclidean distance from p to its nearest point of Q,
    CD = 0.5 * ( mean_{a in A} d(a, B) + mean_{b in B} d(b, A) )      [metres],
the symmetric mean of the two mean nearest-neighbour distances (not squared).

Normal consistency (normal_consistency): with A sampled on the reconstruction as above and B on
the true surface, the mean over a in A of |cos| between the face normal at a and the face normal at
a's nearest point of B, as in the occupancy-network papers (1 = every reconstructed surface element
faces as the true surface next to it; a lumpy blob scores low even where it is close).

Volumetric IoU (volumetric_iou): both closed meshes are voxelized (voxel centres inside, ray
parity, arm_reconstruction.grid.voxelize_mesh) in one cubic grid that encloses both meshes with a
one-voxel margin, |A and B| / |A or B|.
"""

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from .grid import GridFrame, voxelize_mesh

DEFAULT_CHAMFER_SAMPLES = 4096
DEFAULT_IOU_RESOLUTION = 64


def sample_surface_points(mesh: trimesh.Trimesh, count: int, seed: int = 0) -> np.ndarray:
    """(count, 3) points uniformly distributed by area over the mesh's triangles (deterministic in
    seed). Raises ValueError for a mesh without area."""
    return sample_surface(mesh, count, seed)[0]


def sample_surface(mesh: trimesh.Trimesh, count: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(points (count, 3), unit face normals at them (count, 3)), uniformly by area (deterministic in
    seed). Raises ValueError for a mesh without area."""
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if len(faces) == 0:
        raise ValueError("cannot sample points on a mesh without faces")
    triangles = vertices[faces]
    areas = 0.5 * np.linalg.norm(np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1)
    total = areas.sum()
    if not np.isfinite(total) or total <= 0:
        raise ValueError("cannot sample points on a mesh with zero surface area")
    rng = np.random.default_rng(seed)
    chosen = rng.choice(len(faces), size=int(count), p=areas / total)
    r1 = np.sqrt(rng.random(int(count)))[:, None]
    r2 = rng.random(int(count))[:, None]
    a, b, c = triangles[chosen, 0], triangles[chosen, 1], triangles[chosen, 2]
    normals = np.cross(b - a, c - a)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-18)
    return (1 - r1) * a + r1 * (1 - r2) * b + r1 * r2 * c, normals


def directed_distances_m(points_from: np.ndarray, points_to: np.ndarray) -> np.ndarray:
    """Distance from each of points_from to its nearest neighbour in points_to, metres."""
    distances, _ = cKDTree(np.asarray(points_to, dtype=np.float64)).query(np.asarray(points_from, dtype=np.float64))
    return distances


def chamfer_distance_m(
    mesh_a: trimesh.Trimesh, mesh_b: trimesh.Trimesh, samples: int = DEFAULT_CHAMFER_SAMPLES, seed: int = 0
) -> float:
    """Symmetric Chamfer distance in metres: 0.5 * (mean nearest-neighbour distance from `samples`
    points on mesh_a to those on mesh_b + the same from mesh_b to mesh_a). Raises ValueError when a
    mesh has no surface."""
    points_a = sample_surface_points(mesh_a, samples, seed)
    points_b = sample_surface_points(mesh_b, samples, seed)
    a_to_b = directed_distances_m(points_a, points_b).mean()
    b_to_a = directed_distances_m(points_b, points_a).mean()
    return float(0.5 * (a_to_b + b_to_a))


def normal_consistency(
    reconstructed: trimesh.Trimesh, truth: trimesh.Trimesh, samples: int = DEFAULT_CHAMFER_SAMPLES, seed: int = 0
) -> float:
    """Mean |cos| between the normal at each of `samples` points on the reconstructed surface and the
    normal at its nearest point sampled on the true surface (0-1, higher is better). Raises ValueError
    when a mesh has no surface."""
    points, normals = sample_surface(reconstructed, samples, seed)
    true_points, true_normals = sample_surface(truth, samples, seed)
    _, nearest = cKDTree(true_points).query(points)
    return float(np.mean(np.abs(np.einsum("ij,ij->i", normals, true_normals[nearest]))))


def is_closed(mesh: trimesh.Trimesh) -> bool:
    """Every edge is shared by an even number of faces: the inside is defined by ray parity (also for
    surfaces that touch themselves along an edge, which trimesh does not call watertight)."""
    if len(mesh.faces) == 0:
        return False
    _, counts = np.unique(np.asarray(mesh.edges_sorted), axis=0, return_counts=True)
    return bool(np.all(counts % 2 == 0))


def enclosing_grid(meshes, resolution: int = DEFAULT_IOU_RESOLUTION) -> GridFrame:
    """Cubic GridFrame of resolution^3 voxels enclosing every non-empty mesh with one voxel to spare."""
    bounds = [np.asarray(m.bounds) for m in meshes if len(m.faces)]
    if not bounds:
        raise ValueError("no non-empty mesh to enclose")
    lo = np.min([b[0] for b in bounds], axis=0)
    hi = np.max([b[1] for b in bounds], axis=0)
    voxel = max(float(np.max(hi - lo)), 1e-6) / (int(resolution) - 2)
    centre = 0.5 * (lo + hi)
    origin = centre - 0.5 * voxel * int(resolution)
    return GridFrame(origin, voxel, int(resolution), float(origin[2]), "given")


def volumetric_iou(
    mesh_a: trimesh.Trimesh,
    mesh_b: trimesh.Trimesh,
    resolution: int = DEFAULT_IOU_RESOLUTION,
    frame: GridFrame | None = None,
) -> float:
    """Intersection over union of the voxels whose centres lie inside each mesh, in `frame` (default:
    the cubic grid enclosing both). An empty mesh occupies nothing (IoU 0 against a non-empty one).
    Raises ValueError when a non-empty mesh is not closed or when both are empty."""
    for name, mesh in (("mesh_a", mesh_a), ("mesh_b", mesh_b)):
        if len(mesh.faces) and not is_closed(mesh):
            raise ValueError(f"{name} is not a closed surface: its inside is undefined")
    if not len(mesh_a.faces) and not len(mesh_b.faces):
        raise ValueError("both meshes are empty")
    if resolution < 8:
        raise ValueError(f"resolution must be >= 8, got {resolution}")
    frame = frame or enclosing_grid([mesh_a, mesh_b], resolution)
    occupied_a = voxelize_mesh(mesh_a, frame) if len(mesh_a.faces) else np.zeros((frame.resolution,) * 3, bool)
    occupied_b = voxelize_mesh(mesh_b, frame) if len(mesh_b.faces) else np.zeros((frame.resolution,) * 3, bool)
    union = np.count_nonzero(occupied_a | occupied_b)
    return float(np.count_nonzero(occupied_a & occupied_b) / union) if union else 0.0
