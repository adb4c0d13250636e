"""Fast approximate convex decomposition for simulation (replaces V-HACD / CoACD on the hot path).

Hierarchical plane splitting on exact solids (manifold3d): simplify the mesh within
simplify_tolerance_m (fewer triangles to cut, same shape to about a millimetre), start from its
connected pieces (pieces under 0.5 % of its volume are dropped);
while the pieces' total concavity (hull volume - piece volume) exceeds concavity_tolerance * mesh
volume and fewer than max_parts pieces exist, split the most concave piece by the axis-aligned plane
(candidates at fixed fractions of its bounding box) that minimises the summed hull volume of the two
halves. Every piece lies in its own convex cell, so the parts' hulls are disjoint and
IoU(union of parts, mesh) = mesh volume / summed part volume >= 1 / (1 + concavity_tolerance) before
the vertex cap. Each part keeps at most max_vertices hull vertices (support points in spread
directions), which suits MuJoCo. Results are cached by mesh content and settings.
"""

import hashlib
from collections import OrderedDict
from dataclasses import astuple, dataclass

import manifold3d
import numpy as np
import trimesh

from arm_core.settings import setting
from arm_sim.coacd_import import import_coacd

from .meshing import from_manifold, to_manifold

SPLIT_FRACTIONS = (0.25, 0.5, 0.75)
MIN_PART_VOLUME_FRACTION = 5e-3  # specks below 0.5 % of the volume would take part slots
_AXES = np.eye(3)


@dataclass(frozen=True)
class DecompositionSettings:
    """max_parts: cap on convex parts per object; max_vertices: cap on hull vertices per part;
    concavity_tolerance: allowed summed concavity as a fraction of the mesh volume; method: 'planes'
    (this module's fast path), 'coacd' (CoACD with tuned settings, seconds per object) or 'hull';
    simplify_tolerance_m: how far (metres) the 'planes' path may move the surface when it first
    simplifies the mesh (0 keeps every triangle)."""

    max_parts: int = setting(
        8, "Convex parts per object at most (the planner's twin cost grows with them)", 1, 64, parameter=True
    )
    max_vertices: int = setting(64, "Hull vertices per convex part at most", 4, 256)
    concavity_tolerance: float = 0.05
    method: str = "planes"
    simplify_tolerance_m: float = 0.001

    def __post_init__(self):
        if not 1 <= int(self.max_parts) <= 256:
            raise ValueError(f"max_parts must be in [1, 256], got {self.max_parts}")
        if not 4 <= int(self.max_vertices) <= 1024:
            raise ValueError(f"max_vertices must be in [4, 1024], got {self.max_vertices}")
        if not 0.0 <= float(self.concavity_tolerance) <= 10.0:
            raise ValueError(f"concavity_tolerance must be in [0, 10], got {self.concavity_tolerance}")
        if not 0.0 <= float(self.simplify_tolerance_m) <= 0.01:
            raise ValueError(f"simplify_tolerance_m must be in [0, 0.01] m, got {self.simplify_tolerance_m}")
        if self.method not in ("planes", "coacd", "hull"):
            raise ValueError(f"unknown decomposition method '{self.method}' (planes, coacd, hull)")


def _support_directions(count: int) -> np.ndarray:
    """count unit vectors spread evenly over the sphere (Fibonacci lattice)."""
    index = np.arange(count) + 0.5
    polar = np.arccos(1.0 - 2.0 * index / count)
    azimuth = np.pi * (1.0 + 5.0**0.5) * index
    return np.stack([np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar), np.cos(polar)], 1)


def cap_vertices(points: np.ndarray, max_vertices: int) -> np.ndarray:
    """At most max_vertices of points: the extreme point along each of max_vertices directions spread
    over the sphere (after normalising the points' extent so elongated parts are sampled evenly)."""
    points = np.unique(np.asarray(points, dtype=np.float64), axis=0)
    if len(points) <= max_vertices:
        return points
    centre = points.mean(0)
    scale = np.maximum(np.ptp(points, axis=0), 1e-12)
    extreme = np.argmax(((points - centre) / scale) @ _support_directions(max_vertices).T, axis=0)
    return points[np.unique(extreme)]


def _hull_volume(solid: manifold3d.Manifold) -> tuple[manifold3d.Manifold, float]:
    hull = solid.hull()
    return hull, hull.volume()


class _Piece:
    __slots__ = ("solid", "volume", "hull", "hull_volume", "final")

    def __init__(self, solid: manifold3d.Manifold):
        self.solid = solid
        self.volume = solid.volume()
        self.hull, self.hull_volume = _hull_volume(solid)
        self.final = False

    @property
    def concavity(self) -> float:
        return 0.0 if self.final else max(self.hull_volume - self.volume, 0.0)


def _split_hull_volumes(vertices: np.ndarray, edges: np.ndarray, axis: int, offset: float) -> float | None:
    """Summed hull volume of the two halves of a closed mesh (vertices, edges (E, 2)) cut by the plane
    x[axis] = offset, without cutting it: a half's hull is the hull of the vertices on its side and the
    points where edges cross the plane. None when the plane leaves one side empty."""
    signed = vertices[:, axis] - offset
    above, below = signed > 0, signed < 0
    if not above.any() or not below.any():
        return None
    a, b = signed[edges[:, 0]], signed[edges[:, 1]]
    crossing = a * b < 0
    t = (a[crossing] / (a[crossing] - b[crossing]))[:, None]
    start, end = vertices[edges[crossing, 0]], vertices[edges[crossing, 1]]
    section = start + t * (end - start)
    volume = 0.0
    for side in (above, below):
        points = np.ascontiguousarray(np.concatenate([vertices[side], section]))
        volume += manifold3d.Manifold.hull_points(points).volume()
    return volume


def _best_split(piece: _Piece, min_volume: float) -> list[_Piece] | None:
    """The piece's two halves (split into their connected pieces over min_volume) by the candidate
    axis-aligned plane whose halves have the least summed hull volume, or None when no plane lowers it."""
    lo, hi = (np.asarray(c) for c in np.asarray(piece.solid.bounding_box()).reshape(2, 3))
    mesh = piece.solid.to_mesh()
    vertices = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3]
    edges = np.asarray(mesh.tri_verts, dtype=np.int64)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    best_cost, best_plane = piece.hull_volume, None
    for axis in range(3):
        if hi[axis] - lo[axis] <= 1e-9:
            continue
        for fraction in SPLIT_FRACTIONS:
            offset = float(lo[axis] + fraction * (hi[axis] - lo[axis]))
            cost = _split_hull_volumes(vertices, edges, axis, offset)
            if cost is not None and cost < best_cost - 1e-12:
                best_cost, best_plane = cost, (axis, offset)
    if best_plane is None:
        return None
    axis, offset = best_plane
    pieces = []
    for half in piece.solid.split_by_plane(tuple(_AXES[axis]), offset):
        pieces.extend(_Piece(c) for c in half.decompose() if c.volume() > min_volume)
    return pieces or None


def _plane_decomposition(solid: manifold3d.Manifold, settings: DecompositionSettings) -> list[np.ndarray]:
    if settings.simplify_tolerance_m > 0:
        solid = solid.simplify(float(settings.simplify_tolerance_m))
    total = solid.volume()
    min_volume = MIN_PART_VOLUME_FRACTION * total
    pieces = [_Piece(c) for c in solid.decompose() if c.volume() > min_volume]
    budget = settings.concavity_tolerance * total
    while pieces and len(pieces) < settings.max_parts:
        concavities = np.array([p.concavity for p in pieces])
        if concavities.sum() <= budget:
            break
        worst = int(np.argmax(concavities))
        halves = _best_split(pieces[worst], min_volume)
        if halves is None or len(pieces) - 1 + len(halves) > settings.max_parts:
            pieces[worst].final = True
            continue
        pieces[worst : worst + 1] = halves
    return [np.asarray(p.hull.to_mesh().vert_properties)[:, :3] for p in pieces]


def _coacd_decomposition(mesh: trimesh.Trimesh, settings: DecompositionSettings) -> list[np.ndarray]:
    # Imported here: CoACD is an optional backend (not the default 'planes') and its import takes
    # ~0.1 s (python -X importtime), which every reconstruction_node start would pay.
    coacd = import_coacd()
    coacd.set_log_level("error")
    parts = coacd.run_coacd(
        coacd.Mesh(np.asarray(mesh.vertices), np.asarray(mesh.faces)),
        threshold=max(settings.concavity_tolerance, 0.01),
        max_convex_hull=settings.max_parts,
        preprocess_mode="off",
        resolution=300,
        mcts_nodes=8,
        mcts_iterations=15,
        mcts_max_depth=2,
        max_ch_vertex=settings.max_vertices,
    )
    return [np.asarray(vertices) for vertices, _ in parts]


def _hull_mesh(points: np.ndarray) -> trimesh.Trimesh | None:
    if len(points) < 4:
        return None
    hull = manifold3d.Manifold.hull_points(np.ascontiguousarray(points, dtype=np.float64))
    if hull.is_empty() or hull.volume() <= 0:
        return None
    return from_manifold(hull)


class ConvexDecomposer:
    """Decomposes world- or object-frame meshes into convex parts with an LRU cache."""

    def __init__(self, settings: DecompositionSettings | None = None, cache_size: int = 256):
        self.settings = settings or DecompositionSettings()
        self.cache_size = int(cache_size)
        self._cache: OrderedDict[str, list[np.ndarray]] = OrderedDict()
        self.cache_hits = 0

    def clear_cache(self) -> None:
        self._cache.clear()
        self.cache_hits = 0

    def _key(self, mesh: trimesh.Trimesh) -> str:
        sha = hashlib.sha1(np.ascontiguousarray(mesh.vertices, dtype=np.float32).tobytes())
        sha.update(np.ascontiguousarray(mesh.faces, dtype=np.int64).tobytes())
        sha.update(repr(astuple(self.settings)).encode())
        return sha.hexdigest()

    def __call__(self, mesh: trimesh.Trimesh) -> list[trimesh.Trimesh]:
        """Convex parts (watertight trimesh hulls, <= max_vertices vertices each) of mesh; [] for an
        empty mesh. A mesh that is not a closed manifold gets its convex hull as the single part."""
        if len(mesh.faces) == 0:
            return []
        key = self._key(mesh)
        if key in self._cache:
            self._cache.move_to_end(key)
            self.cache_hits += 1
            point_sets = self._cache[key]
        else:
            point_sets = self._decompose(mesh)
            self._cache[key] = point_sets
            if len(self._cache) > self.cache_size:
                self._cache.popitem(last=False)
        parts = [_hull_mesh(cap_vertices(p, self.settings.max_vertices)) for p in point_sets]
        return [p for p in parts if p is not None]

    def _decompose(self, mesh: trimesh.Trimesh) -> list[np.ndarray]:
        solid = to_manifold(mesh)
        if solid is None or self.settings.method == "hull" or self.settings.max_parts == 1:
            return [np.asarray(mesh.vertices)]
        if self.settings.method == "coacd":
            return _coacd_decomposition(mesh, self.settings)
        return _plane_decomposition(solid, self.settings)


def decomposition_iou(mesh: trimesh.Trimesh, parts: list[trimesh.Trimesh]) -> float:
    """Volume IoU between the union of the convex parts and the mesh (exact, manifold3d booleans)."""
    solid = to_manifold(mesh)
    hulls = [to_manifold(p) for p in parts]
    hulls = [h for h in hulls if h is not None]
    if solid is None or not hulls:
        return 0.0
    union = manifold3d.Manifold.batch_boolean(hulls, manifold3d.OpType.Add)
    union_volume = (union + solid).volume()
    return float((union ^ solid).volume() / union_volume) if union_volume > 0 else 0.0
