"""Object library: procedural household-like shapes and external mesh folders.

Every object is a watertight mesh in metres plus its convex parts. Procedural objects are built
from convex parts (so their decomposition is exact) and their mesh is the boolean union of the
parts. The object frame's origin is the bottom centre of the bounding box: an upright object
rests on the z = 0 plane of its own frame.
"""

import hashlib
import pathlib
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import trimesh

from arm_sim.coacd_import import import_coacd

NOMINAL_EXTENT_M = 0.08
MESH_SUFFIXES = (".obj", ".stl", ".ply")


@dataclass
class ObjectModel:
    name: str
    category: str
    mesh: trimesh.Trimesh
    convex_parts: list[trimesh.Trimesh] = field(default_factory=list)

    def scaled(self, scale: float) -> "ObjectModel":
        mesh = self.mesh.copy()
        mesh.apply_scale(scale)
        parts = []
        for part in self.convex_parts:
            p = part.copy()
            p.apply_scale(scale)
            parts.append(p)
        return ObjectModel(self.name, self.category, mesh, parts)


def _hull(points: np.ndarray) -> trimesh.Trimesh:
    return trimesh.convex.convex_hull(np.asarray(points, dtype=np.float64))


def _circle(radius: float, z: float, sections: int, centre=(0.0, 0.0)) -> np.ndarray:
    angle = np.linspace(0.0, 2 * np.pi, sections, endpoint=False)
    return np.stack([centre[0] + radius * np.cos(angle), centre[1] + radius * np.sin(angle), np.full(sections, z)], 1)


def frustum(r_bottom: float, r_top: float, z0: float, z1: float, sections: int = 24) -> trimesh.Trimesh:
    return _hull(np.concatenate([_circle(r_bottom, z0, sections), _circle(r_top, z1, sections)]))


def box(extents, centre=(0.0, 0.0, 0.0)) -> trimesh.Trimesh:
    return trimesh.creation.box(extents=extents, transform=trimesh.transformations.translation_matrix(centre))


def revolved_shell(
    radii_outer: np.ndarray, heights: np.ndarray, thickness: float, wedges: int = 10, arc_points: int = 4
) -> list[trimesh.Trimesh]:
    """Thin-walled surface of revolution as convex wedge pieces, one per (band, wedge)."""
    parts = []
    edges = np.linspace(0.0, 2 * np.pi, wedges + 1)
    for band in range(len(heights) - 1):
        z0, z1 = heights[band], heights[band + 1]
        r0, r1 = radii_outer[band], radii_outer[band + 1]
        for w in range(wedges):
            angle = np.linspace(edges[w], edges[w + 1], arc_points)
            pts = []
            for z, r in ((z0, r0), (z1, r1)):
                ri = max(r - thickness, 1e-4)
                pts.append(np.stack([r * np.cos(angle), r * np.sin(angle), np.full(arc_points, z)], 1))
                pts.append(np.stack([ri * np.cos(angle[[0, -1]]), ri * np.sin(angle[[0, -1]]), [z, z]], 1))
            parts.append(_hull(np.concatenate(pts)))
    return parts


def torus_arc(major: float, minor: float, centre, start: float, stop: float, pieces: int = 6) -> list[trimesh.Trimesh]:
    """A handle: an arc of a torus in the x-z plane as convex capsule-like pieces."""
    angles = np.linspace(start, stop, pieces + 1)
    centre = np.asarray(centre, dtype=np.float64)
    parts = []
    for a0, a1 in zip(angles[:-1], angles[1:], strict=True):
        pts = []
        for a in (a0, a1):
            c = centre + major * np.array([np.cos(a), 0.0, np.sin(a)])
            sphere = trimesh.creation.icosphere(subdivisions=1, radius=minor).vertices + c
            pts.append(sphere)
        parts.append(_hull(np.concatenate(pts)))
    return parts


def _can(rng):
    r, h = rng.uniform(0.025, 0.045), rng.uniform(0.06, 0.14)
    return [frustum(r, r, 0.0, h, 28)]


def _bottle(rng):
    r, h = rng.uniform(0.02, 0.04), rng.uniform(0.12, 0.22)
    neck = rng.uniform(0.25, 0.45) * r
    shoulder = h * rng.uniform(0.55, 0.7)
    return [
        frustum(r, r, 0.0, shoulder),
        frustum(r, neck, shoulder, shoulder + 0.25 * (h - shoulder) + 0.01),
        frustum(neck, neck, shoulder, h),
    ]


def _box(rng):
    e = rng.uniform([0.03, 0.03, 0.02], [0.12, 0.09, 0.2])
    return [box(e, (0, 0, e[2] / 2))]


def _cup_like(rng, handle: bool, taper: float, height_range, radius_range):
    r, h = rng.uniform(*radius_range), rng.uniform(*height_range)
    wall = max(0.004, 0.08 * r)
    heights = np.linspace(wall, h, 3)
    radii = np.linspace(r * taper, r, 3)
    parts = [frustum(r * taper, r * taper + (r - r * taper) * wall / h, 0.0, wall)]
    parts += revolved_shell(radii, heights, wall)
    if handle:
        parts += torus_arc(0.35 * h, 0.15 * r, (r, 0.0, 0.5 * h), -np.pi / 2, np.pi / 2)
    return parts


def _mug(rng):
    return _cup_like(rng, True, 1.0, (0.07, 0.11), (0.03, 0.045))


def _cup(rng):
    return _cup_like(rng, False, rng.uniform(0.65, 0.85), (0.07, 0.12), (0.03, 0.045))


def _bowl(rng):
    r, h = rng.uniform(0.05, 0.09), rng.uniform(0.035, 0.06)
    wall = max(0.004, 0.06 * r)
    z = np.linspace(wall, h, 4)
    radii = 0.45 * r + 0.55 * r * np.sqrt(np.linspace(0.0, 1.0, 4))
    return [frustum(0.45 * r, 0.45 * r, 0.0, wall)] + revolved_shell(radii, z, wall)


def _jar(rng):
    r, h = rng.uniform(0.03, 0.05), rng.uniform(0.07, 0.13)
    lid = rng.uniform(0.7, 0.9) * r
    return [frustum(r, r, 0.0, h * 0.85), frustum(lid, lid, h * 0.8, h)]


def _ball(rng):
    r = rng.uniform(0.025, 0.05)
    return [trimesh.creation.icosphere(subdivisions=2, radius=r).apply_translation((0, 0, r))]


def _l_shape(rng):
    t = rng.uniform(0.02, 0.04)
    a, b = rng.uniform(0.06, 0.12), rng.uniform(0.06, 0.14)
    depth = rng.uniform(0.03, 0.06)
    return [box((a, depth, t), (a / 2, 0, t / 2)), box((t, depth, b), (t / 2, 0, b / 2))]


def _wine_glass(rng):
    r, h = rng.uniform(0.03, 0.045), rng.uniform(0.14, 0.2)
    foot, stem = rng.uniform(0.6, 0.9) * r, 0.12 * r
    stem_top = h * rng.uniform(0.35, 0.5)
    wall = 0.004
    z = np.linspace(stem_top, h, 4)
    radii = r * np.array([0.25, 0.8, 1.0, 0.9])
    return (
        [frustum(foot, foot, 0.0, 0.006), frustum(stem, stem, 0.0, stem_top + 0.005)]
        + revolved_shell(radii, z, wall)
        + [frustum(0.25 * r, 0.25 * r, stem_top, stem_top + wall)]
    )


def _vase(rng):
    r, h = rng.uniform(0.035, 0.06), rng.uniform(0.14, 0.26)
    z = np.linspace(0.0, h, 5)
    radii = r * np.array([0.7, 1.0, 0.85, 0.45, rng.uniform(0.5, 0.8)])
    return [frustum(radii[i], radii[i + 1], z[i], z[i + 1]) for i in range(4)]


def _lamp(rng):
    base_r, h = rng.uniform(0.04, 0.07), rng.uniform(0.18, 0.3)
    pole = rng.uniform(0.006, 0.012)
    shade_r = rng.uniform(0.05, 0.09)
    shade_h = rng.uniform(0.05, 0.09)
    parts = [frustum(base_r, base_r * 0.8, 0.0, 0.015), frustum(pole, pole, 0.0, h - shade_h * 0.5)]
    parts.append(frustum(shade_r, shade_r * 0.6, h - shade_h, h))
    return parts


def _t_shape(rng):
    t = rng.uniform(0.02, 0.035)
    bar, stem = rng.uniform(0.08, 0.14), rng.uniform(0.06, 0.12)
    depth = rng.uniform(0.03, 0.06)
    return [box((bar, depth, t), (0, 0, stem + t / 2)), box((t, depth, stem + t / 2), (0, 0, (stem + t / 2) / 2))]


def _trophy(rng):
    r, h = rng.uniform(0.03, 0.05), rng.uniform(0.14, 0.22)
    base = box((2.2 * r, 2.2 * r, 0.02), (0, 0, 0.01))
    stem = frustum(0.2 * r, 0.2 * r, 0.0, h * 0.5)
    cup = revolved_shell(np.array([0.3 * r, r, 1.1 * r]), np.array([h * 0.5, h * 0.8, h]), 0.004, wedges=8)
    handles = torus_arc(0.15 * h, 0.1 * r, (1.05 * r, 0, 0.8 * h), -np.pi / 2, np.pi / 2, 4)
    handles += [p.copy().apply_transform(trimesh.transformations.rotation_matrix(np.pi, (0, 0, 1))) for p in handles]
    return [base, stem, frustum(0.3 * r, 0.3 * r, h * 0.5, h * 0.5 + 0.004)] + cup + handles


CATEGORY_BUILDERS: dict[str, Callable[[np.random.Generator], list[trimesh.Trimesh]]] = {
    "can": _can,
    "bottle": _bottle,
    "box": _box,
    "mug": _mug,
    "bowl": _bowl,
    "cup": _cup,
    "jar": _jar,
    "ball": _ball,
    "l_shape": _l_shape,
    "wine_glass": _wine_glass,
    "vase": _vase,
    "lamp": _lamp,
    "t_shape": _t_shape,
    "trophy": _trophy,
}
TRAIN_CATEGORIES = ("can", "bottle", "box", "mug", "bowl", "cup", "jar", "ball", "l_shape")
HELDOUT_CATEGORIES = ("wine_glass", "vase", "lamp", "t_shape", "trophy")


def union_mesh(parts: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    """Watertight boolean union of convex parts (manifold3d engine)."""
    if len(parts) == 1:
        return parts[0].copy()
    return trimesh.boolean.union(parts, engine="manifold")


def _normalise(parts: list[trimesh.Trimesh], extent_m: float | None) -> list[trimesh.Trimesh]:
    """Move the bottom centre of the bounding box to the origin; optionally scale to extent_m."""
    lo = np.min([p.bounds[0] for p in parts], axis=0)
    hi = np.max([p.bounds[1] for p in parts], axis=0)
    shift = -np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    scale = 1.0 if extent_m is None else extent_m / float(np.max(hi - lo))
    out = []
    for p in parts:
        q = p.copy()
        q.apply_translation(shift)
        q.apply_scale(scale)
        out.append(q)
    return out


def make_object(category: str, rng: np.random.Generator, extent_m: float | None = NOMINAL_EXTENT_M) -> ObjectModel:
    """One random instance of a procedural category, its largest side scaled to extent_m metres."""
    if category not in CATEGORY_BUILDERS:
        raise ValueError(f"unknown category '{category}', known: {sorted(CATEGORY_BUILDERS)}")
    parts = _normalise(CATEGORY_BUILDERS[category](rng), extent_m)
    mesh = union_mesh(parts)
    name = f"{category}_{int(rng.integers(1 << 31)):08x}"
    return ObjectModel(name, category, mesh, parts)


def load_mesh_file(path: pathlib.Path, max_parts: int = 12) -> ObjectModel:
    """An external mesh (metres) -> ObjectModel; convex parts from CoACD, cached beside the user's home."""
    mesh = trimesh.load(path, force="mesh", process=True)
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ValueError(f"{path}: no triangles")
    if not mesh.is_watertight:
        trimesh.repair.fill_holes(mesh)
    if not mesh.is_watertight:
        mesh = mesh.convex_hull
    parts = _normalise([mesh], None)
    mesh = parts[0]
    return ObjectModel(path.stem, "external", mesh, decompose_cached(mesh, max_parts))


def decompose_cached(mesh: trimesh.Trimesh, max_parts: int = 12) -> list[trimesh.Trimesh]:
    """Convex decomposition of an external mesh with CoACD, cached on disk by mesh hash."""
    digest = hashlib.sha256(mesh.vertices.tobytes() + mesh.faces.tobytes()).hexdigest()[:24]
    cache = pathlib.Path.home() / ".cache" / "arm_ros" / "coacd" / f"{digest}_{max_parts}.npz"
    if cache.exists():
        data = np.load(cache)
        return [_hull(data[k]) for k in sorted(data.files)]
    coacd = import_coacd()
    coacd.set_log_level("error")
    result = coacd.run_coacd(
        coacd.Mesh(mesh.vertices, mesh.faces), threshold=0.08, max_convex_hull=max_parts, preprocess_resolution=30
    )
    parts = [_hull(v) for v, _ in result]
    cache.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(cache, **{f"p{i:03d}": p.vertices for i, p in enumerate(parts)})
    return parts


class ObjectPool:
    """A set of object sources to sample scene objects from."""

    def __init__(self, categories=(), models=(), seed: int = 0):
        self.categories = tuple(categories)
        self.models = list(models)
        if not self.categories and not self.models:
            raise ValueError("an object pool needs categories or meshes")

    def __len__(self) -> int:
        return len(self.models) if self.models else len(self.categories)

    def sample(self, rng: np.random.Generator) -> ObjectModel:
        if self.models:
            return self.models[int(rng.integers(len(self.models)))]
        return make_object(self.categories[int(rng.integers(len(self.categories)))], rng)


def object_pool(objects: str | None = None, split: str = "train", seed: int = 0) -> ObjectPool:
    """objects=None: the procedural categories of split ('train' or 'heldout'); else a mesh folder."""
    if objects:
        folder = pathlib.Path(objects)
        files = sorted(p for p in folder.iterdir() if p.suffix.lower() in MESH_SUFFIXES) if folder.is_dir() else []
        if not files:
            raise ValueError(f"--objects {objects}: no .obj/.stl/.ply meshes found")
        return ObjectPool(models=[load_mesh_file(p) for p in files], seed=seed)
    if split not in ("train", "heldout"):
        raise ValueError(f"split must be 'train' or 'heldout', got '{split}'")
    return ObjectPool(categories=TRAIN_CATEGORIES if split == "train" else HELDOUT_CATEGORIES, seed=seed)
