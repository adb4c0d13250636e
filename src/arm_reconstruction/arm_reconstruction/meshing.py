"""Occupancy probabilities -> simulation-ready world-frame meshes (paper Section 3.1, post-processing).

Add the observed voxels the network missed, threshold, drop components apart from the observed
voxels and specks, extend a floating result down to its support, marching cubes (scikit-image)
on the zero-padded probability field (closed, watertight surfaces; the surface crosses the threshold
between voxel centres), back to the world frame, then inter-object intersection removal that cuts
from the larger mesh (manifold3d booleans). Also the inference-time method variants: ray carving and
extrusion down to the table.
"""

import manifold3d
import numpy as np
import scipy.spatial
import trimesh
from scipy import ndimage
from skimage.measure import marching_cubes

from .grid import GridFrame

DEFAULT_THRESHOLD = 0.5
DEFAULT_MIN_COMPONENT_VOXELS = 4
DEFAULT_SMOOTHING_ITERATIONS = 0
DEFAULT_STABLE_BASE_TILT_DEG = 20.0
MIN_CUT_VOLUME_M3 = 1e-9


def ray_carve(probabilities: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """'baseline+ray carving': probabilities with every observed-empty voxel (F3) set to 0."""
    return np.where(np.asarray(grid)[2] > 0, np.float32(0.0), probabilities).astype(np.float32)


def extrude_to_table(probabilities: np.ndarray) -> np.ndarray:
    """'baseline+E': every voxel takes the largest probability at or above it in its column, so the
    thresholded shape is the prediction swept straight down to the table (grid z = 0)."""
    flipped = np.flip(np.asarray(probabilities), axis=2)
    return np.flip(np.maximum.accumulate(flipped, axis=2), axis=2).astype(np.float32)


def drop_small_components(
    probabilities: np.ndarray, threshold: float, min_voxels: int = DEFAULT_MIN_COMPONENT_VOXELS
) -> np.ndarray:
    """Zero the probabilities of 6-connected occupied components smaller than min_voxels; the largest
    component is always kept (a thin object may occupy only a few voxels)."""
    occupied = probabilities > threshold
    if min_voxels <= 1 or not occupied.any():
        return probabilities
    labels, count = ndimage.label(occupied)
    sizes = np.bincount(labels.ravel(), minlength=count + 1)
    sizes[0] = 0
    small = sizes < min_voxels
    small[0] = False
    small[int(np.argmax(sizes))] = False
    return np.where(small[labels], np.float32(0.0), probabilities).astype(np.float32)


def keep_observed_components(probabilities: np.ndarray, threshold: float, observed: np.ndarray) -> np.ndarray:
    """Zero the probabilities of occupied components (6-connected) that touch no observed voxel of
    the object (F1, within one voxel): a connected rigid object contains what was seen of it, so a
    component apart from it is not the object. Unchanged when no component touches (or none was seen)."""
    occupied = probabilities > threshold
    seen = np.asarray(observed) > 0
    if not occupied.any() or not seen.any():
        return probabilities
    labels, count = ndimage.label(occupied)
    near_seen = ndimage.binary_dilation(seen, structure=np.ones((3, 3, 3), bool))
    touching = np.zeros(count + 1, bool)
    touching[np.unique(labels[near_seen & occupied])] = True
    if not touching.any():
        return probabilities
    return np.where(occupied & ~touching[labels], np.float32(0.0), probabilities).astype(np.float32)


def add_missed_observed_voxels(
    probabilities: np.ndarray,
    threshold: float,
    observed: np.ndarray,
    max_bridge_rounds: int = 4,
    min_part_voxels: int = DEFAULT_MIN_COMPONENT_VOXELS,
) -> np.ndarray:
    """Set to 1 the object's observed voxels (F1) that the predicted occupancy misses: what was seen of
    an object is part of it. Observed voxels farther than one voxel (26-neighbourhood) from the
    prediction are added. Those next to it are left to it, so its surface is not thickened by depth
    noise, except in the bottom layer (grid z = 0), where what was seen is the object's footprint on
    the table (the base of a stemmed glass, next to its one-voxel stem), and where one joins two
    separate occupied parts (6-connected, of at least min_part_voxels each), which a rigid object is
    not: up to max_bridge_rounds rounds of such bridges."""
    seen = np.asarray(observed) > 0
    occupied = probabilities > threshold
    cube, six = np.ones((3, 3, 3), bool), ndimage.generate_binary_structure(3, 1)
    occupied = occupied | (seen & ~ndimage.binary_dilation(occupied, structure=cube))
    occupied[:, :, 0] |= seen[:, :, 0]
    candidates = seen & ~occupied
    for _ in range(max_bridge_rounds):
        labels, count = ndimage.label(occupied, structure=six)
        if count < 2 or not candidates.any():
            break
        labels[np.bincount(labels.ravel())[labels] < min_part_voxels] = 0
        highest = ndimage.maximum_filter(labels, footprint=six, mode="constant", cval=0)
        lowest = ndimage.minimum_filter(
            np.where(labels > 0, labels, count + 1), footprint=six, mode="constant", cval=count + 1
        )
        bridges = candidates & (highest > 0) & (lowest <= count) & (highest != lowest)
        if not bridges.any():
            break
        occupied |= bridges
        candidates &= ~bridges
    return np.where(occupied & ~(probabilities > threshold), np.float32(1.0), probabilities).astype(np.float32)


def rests_on_support(occupied: np.ndarray, other_observed: np.ndarray) -> bool:
    """Whether an occupied grid [d, d, d] (+z up, layer 0 on the table) touches the table or rests on
    another object's observed voxels (F2) directly below one of its voxels."""
    occupied = np.asarray(occupied, bool)
    if occupied[:, :, 0].any():
        return True
    return bool((occupied[:, :, 1:] & (np.asarray(other_observed)[:, :, :-1] > 0)).any())


def support_from_below(probabilities: np.ndarray, threshold: float, grid: np.ndarray) -> np.ndarray:
    """A scene at rest has no floating objects: when the occupancy above threshold rests on nothing
    (rests_on_support), each of its columns is extended straight down through unobserved voxels (F4)
    to the table or to whatever stops it; seen voxels (F1-F3) are never filled. Unchanged when the
    object is supported or empty."""
    grid = np.asarray(grid)
    occupied = probabilities > threshold
    if not occupied.any() or rests_on_support(occupied, grid[1]):
        return probabilities
    fillable = grid[3] > 0
    filled = occupied.copy()
    for z in range(occupied.shape[2] - 2, -1, -1):  # one layer at a time, top down
        filled[:, :, z] |= filled[:, :, z + 1] & fillable[:, :, z]
    return np.where(filled & ~occupied, np.float32(1.0), probabilities).astype(np.float32)


def _axis_path(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Voxels (K, 3) of a 6-connected path from start to end (both included) along the straight line:
    the line's voxels, with a diagonal step between two of them split into one step per axis."""
    start, end = np.asarray(start, dtype=np.int64), np.asarray(end, dtype=np.int64)
    count = int(np.abs(end - start).max()) + 1
    line = np.rint(np.linspace(start, end, count)).astype(np.int64)
    previous, following = line[:-1], line[1:]
    step_x = np.column_stack([following[:, 0], previous[:, 1:]])
    step_xy = np.column_stack([following[:, :2], previous[:, 2]])
    path = np.concatenate([np.stack([previous, step_x, step_xy], axis=1).reshape(-1, 3), line[-1:]])
    keep = np.concatenate([[True], (np.diff(path, axis=0) != 0).any(axis=1)])
    return path[keep]


def connect_parts(probabilities: np.ndarray, threshold: float, grid: np.ndarray) -> np.ndarray:
    """The connectivity prior at test time: a rigid object is one piece. Each occupied part apart from
    the largest (6-connected) is joined to it by a one-voxel path between their nearest voxels,
    largest part first, unless the path crosses space seen empty (F3) or another object (F2); a part
    that cannot be joined stays as it is (dropping the small ones cost Chamfer: they are seen surface)."""
    occupied = probabilities > threshold
    labels, count = ndimage.label(occupied)
    if count < 2:
        return probabilities
    grid = np.asarray(grid)
    blocked = ((grid[1] > 0) | (grid[2] > 0)) & ~occupied
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    main = labels == int(np.argmax(sizes))
    added = np.zeros_like(occupied)
    for part_label in np.argsort(-sizes)[1:count]:
        part = labels == part_label
        distance, nearest = ndimage.distance_transform_edt(~main, return_indices=True)
        voxels = np.argwhere(part)
        start = voxels[int(np.argmin(distance[part]))]
        path = _axis_path(start, nearest[:, start[0], start[1], start[2]])
        if blocked[tuple(path.T)].any():
            continue
        added[tuple(path.T)] = True
        main |= part
        main[tuple(path.T)] = True
    if not added.any():
        return probabilities
    return np.where(added & ~occupied, np.float32(1.0), probabilities).astype(np.float32)


def widen_unstable_base(probabilities: np.ndarray, threshold: float, grid: np.ndarray, tilt_deg: float) -> np.ndarray:
    """The stability prior at test time: an object standing on the table (grid z = 0) whose centre of
    mass (uniform density over the occupied voxels) lies less than h * tan(tilt_deg) inside its
    footprint (h: the centre's height) would topple at that tilt. Its bottom layer then gains the
    unobserved voxels (F4) under its own shadow within that distance (plus one voxel) of the centre's
    foot: a base, where the view allows one. Unchanged for objects on other objects or stable ones."""
    occupied = probabilities > threshold
    footprint = occupied[:, :, 0]
    if tilt_deg <= 0 or not footprint.any():
        return probabilities
    com = np.argwhere(occupied).mean(axis=0)
    reach = (com[2] + 0.5) * np.tan(np.radians(tilt_deg))  # voxels; the table plane is z = -0.5
    if _inside_margin(footprint, com[:2]) >= reach:
        return probabilities
    ii, jj = np.indices(footprint.shape)
    near_foot = np.hypot(ii - com[0], jj - com[1]) <= reach + 1.0
    base = near_foot & occupied.any(axis=2) & (np.asarray(grid)[3][:, :, 0] > 0) & ~footprint
    if not base.any():
        return probabilities
    out = np.array(probabilities, dtype=np.float32, copy=True)
    out[:, :, 0] = np.where(base, np.float32(1.0), out[:, :, 0])
    return out


def _inside_margin(footprint: np.ndarray, point_ij: np.ndarray) -> float:
    """Signed distance (voxels) from point_ij to the border of the footprint's convex hull (voxel
    squares), positive inside."""
    corners = np.argwhere(footprint)[:, None, :] + np.array([[-0.5, -0.5], [-0.5, 0.5], [0.5, -0.5], [0.5, 0.5]])
    corners = corners.reshape(-1, 2)
    try:
        hull = scipy.spatial.ConvexHull(corners)
    except scipy.spatial.QhullError:
        return -1.0
    # hull.equations: normal . x + offset <= 0 inside; the distance to the nearest facet
    return float(-np.max(hull.equations[:, :2] @ point_ij + hull.equations[:, 2]))


def empty_mesh() -> trimesh.Trimesh:
    return trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64), process=False)


def occupancy_mesh(
    probabilities: np.ndarray,
    frame: GridFrame,
    threshold: float = DEFAULT_THRESHOLD,
    min_component_voxels: int = DEFAULT_MIN_COMPONENT_VOXELS,
    grid: np.ndarray | None = None,
    smoothing_iterations: int = DEFAULT_SMOOTHING_ITERATIONS,
    stable_base_tilt_deg: float = DEFAULT_STABLE_BASE_TILT_DEG,
    join_parts: bool = True,
) -> trimesh.Trimesh:
    """World-frame watertight mesh of the voxels whose probability exceeds threshold (empty mesh when
    none do). smoothing_iterations > 0: Taubin smoothing of the surface (volume-preserving: it takes
    the voxel steps off without shrinking the shape), the base kept flat on the table.
    The grid is zero-padded so that shapes touching the grid faces are closed there; the
    surface below the bottom layer's centres is flattened onto the table plane (grid z = 0), so that
    a shape standing on the table rests on it with a flat base. grid [4, d, d, d]: the object's
    four-channel grid; components apart from its observed voxels (F1) are dropped, then what is
    left is supported from below if it floats (support_from_below), its parts joined (join_parts:
    connect_parts) and given a base if it would topple at stable_base_tilt_deg (widen_unstable_base;
    0: never)."""
    if not 0.0 < threshold < 1.0:
        raise ValueError(f"threshold must be in (0, 1), got {threshold}")
    probabilities = np.nan_to_num(np.asarray(probabilities, dtype=np.float32), nan=0.0)
    d = frame.resolution
    if probabilities.shape != (d, d, d):
        raise ValueError(f"probabilities shape {probabilities.shape} does not match the grid ({d},{d},{d})")
    if grid is not None:
        probabilities = keep_observed_components(probabilities, threshold, np.asarray(grid)[0])
    probabilities = drop_small_components(probabilities, threshold, min_component_voxels)
    if grid is not None:
        probabilities = support_from_below(probabilities, threshold, grid)
        if join_parts:
            probabilities = connect_parts(probabilities, threshold, grid)
        probabilities = widen_unstable_base(probabilities, threshold, grid, stable_base_tilt_deg)
    if not (probabilities > threshold).any():
        return empty_mesh()
    padded = np.pad(probabilities, 1, constant_values=0.0)
    vertices, faces, _, _ = marching_cubes(padded, level=float(threshold), allow_degenerate=False)
    vertices = vertices - 0.5
    if smoothing_iterations > 0:
        voxel_mesh = trimesh.Trimesh(vertices, faces, process=False)
        trimesh.smoothing.filter_taubin(voxel_mesh, lamb=0.5, nu=0.53, iterations=int(smoothing_iterations))
        vertices = np.asarray(voxel_mesh.vertices)
    vertices[:, 2] = np.where(vertices[:, 2] < 0.5, 0.0, vertices[:, 2])
    vertices_world = frame.voxel_to_world(vertices)
    mesh = trimesh.Trimesh(vertices_world, faces[:, ::-1], process=True)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def to_manifold(mesh: trimesh.Trimesh) -> manifold3d.Manifold | None:
    """trimesh -> manifold3d.Manifold, None when the mesh is not a closed 2-manifold."""
    if len(mesh.faces) == 0:
        return None
    solid = manifold3d.Manifold(
        manifold3d.Mesh(
            vert_properties=np.ascontiguousarray(mesh.vertices, dtype=np.float32),
            tri_verts=np.ascontiguousarray(mesh.faces, dtype=np.uint32),
        )
    )
    if solid.status() != manifold3d.Error.NoError or solid.is_empty():
        return None
    return solid


def from_manifold(solid: manifold3d.Manifold) -> trimesh.Trimesh:
    out = solid.to_mesh()
    if len(out.tri_verts) == 0:
        return empty_mesh()
    return trimesh.Trimesh(np.asarray(out.vert_properties)[:, :3], np.asarray(out.tri_verts), process=True)


def remove_intersections(meshes: list[trimesh.Trimesh]) -> tuple[list[trimesh.Trimesh], int]:
    """Remove the overlap of every intersecting pair from the larger mesh of the pair (by volume, as
    in the paper). Pairs are processed from the largest overlap down. Returns (meshes, cuts made);
    meshes that are not closed manifolds are left untouched."""
    solids = [to_manifold(m) for m in meshes]
    volumes = np.array([s.volume() if s is not None else 0.0 for s in solids])
    boxes = np.array([m.bounds if len(m.faces) else np.full((2, 3), np.nan) for m in meshes], dtype=np.float64).reshape(
        len(meshes), 2, 3
    )
    lo, hi = boxes[:, 0], boxes[:, 1]
    overlap = np.all((lo[:, None] < hi[None]) & (lo[None] < hi[:, None]), axis=2)
    candidates = [(a, b) for a, b in zip(*np.nonzero(np.triu(overlap, 1)), strict=True) if solids[a] and solids[b]]
    pairs = []
    for a, b in candidates:
        shared = (solids[a] ^ solids[b]).volume()
        if shared > MIN_CUT_VOLUME_M3:
            pairs.append((shared, int(a), int(b)))
    result = list(meshes)
    cuts = 0
    for _, a, b in sorted(pairs, reverse=True):
        larger, smaller = (a, b) if volumes[a] >= volumes[b] else (b, a)
        if (solids[larger] ^ solids[smaller]).volume() <= MIN_CUT_VOLUME_M3:
            continue
        solids[larger] = solids[larger] - solids[smaller]
        result[larger] = from_manifold(solids[larger])
        cuts += 1
    return result, cuts
