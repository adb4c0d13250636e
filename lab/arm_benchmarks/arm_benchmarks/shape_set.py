"""make_shape_set OUT_DIR: a folder of other object shapes, for checking segmentation on objects it
was never tuned on (bench_seg --objects OUT_DIR).

Trimesh primitives and extrusions of other proportions than the procedural categories: capsules,
tori and rings, thin plates, tall cylinders, boxes, cones, L and U extrusions, 4-30 cm in size.
Every mesh is watertight, in metres, z up, resting on z = 0, written as .obj.
"""

import argparse
import pathlib

import numpy as np
import trimesh

KINDS = ("capsule", "torus", "ring", "plate", "tall_cylinder", "box", "cone", "l_extrusion", "u_extrusion")


def _union(boxes: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    return trimesh.boolean.union(boxes, engine="manifold")


def _box(extents, centre) -> trimesh.Trimesh:
    return trimesh.creation.box(extents=extents, transform=trimesh.transformations.translation_matrix(centre))


def make_shape(kind: str, rng: np.random.Generator) -> trimesh.Trimesh:
    """One shape of `kind` with random proportions; largest extent 4-30 cm."""
    u = rng.uniform
    if kind == "capsule":
        radius = u(0.015, 0.04)
        mesh = trimesh.creation.capsule(height=u(0.04, 0.2), radius=radius)
        if u() < 0.5:  # lying down
            mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    elif kind == "torus":
        major = u(0.04, 0.1)
        mesh = trimesh.creation.torus(major_radius=major, minor_radius=u(0.15, 0.4) * major)
    elif kind == "ring":
        outer = u(0.03, 0.12)
        mesh = trimesh.creation.annulus(r_min=u(0.5, 0.85) * outer, r_max=outer, height=u(0.01, 0.08))
    elif kind == "plate":
        mesh = trimesh.creation.box(extents=[u(0.08, 0.3), u(0.06, 0.25), u(0.006, 0.02)])
    elif kind == "tall_cylinder":
        mesh = trimesh.creation.cylinder(radius=u(0.015, 0.04), height=u(0.15, 0.3))
    elif kind == "box":
        mesh = trimesh.creation.box(extents=[u(0.04, 0.2), u(0.04, 0.2), u(0.04, 0.2)])
    elif kind == "cone":
        mesh = trimesh.creation.cone(radius=u(0.03, 0.1), height=u(0.05, 0.2))
    elif kind == "l_extrusion":
        a, b, t, depth = u(0.08, 0.25), u(0.06, 0.2), u(0.015, 0.04), u(0.03, 0.12)
        mesh = _union([_box([a, t, depth], [a / 2, t / 2, 0]), _box([t, b, depth], [t / 2, b / 2, 0])])
    elif kind == "u_extrusion":
        a, b, t, depth = u(0.08, 0.25), u(0.05, 0.15), u(0.015, 0.04), u(0.03, 0.1)
        mesh = _union(
            [
                _box([a, t, depth], [a / 2, t / 2, 0]),
                _box([t, b, depth], [t / 2, b / 2, 0]),
                _box([t, b, depth], [a - t / 2, b / 2, 0]),
            ]
        )
    else:
        raise ValueError(f"unknown shape kind '{kind}' (one of {', '.join(KINDS)})")
    mesh.apply_translation([-mesh.bounds[:, 0].mean(), -mesh.bounds[:, 1].mean(), -mesh.bounds[0, 2]])
    return mesh


def make_shape_set(out_dir: pathlib.Path, per_kind: int = 2, seed: int = 0) -> list[pathlib.Path]:
    """Write per_kind shapes of every kind to out_dir; returns their paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    paths = []
    for kind in KINDS:
        for i in range(per_kind):
            mesh = make_shape(kind, rng)
            if not mesh.is_watertight:
                raise RuntimeError(f"{kind} {i}: mesh is not watertight")
            path = out_dir / f"{kind}_{i}.obj"
            mesh.export(path)
            paths.append(path)
    return paths


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out_dir", help="folder to write the .obj meshes to")
    parser.add_argument("--per-kind", type=int, default=2, help="shapes of each kind")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    if args.per_kind < 1:
        parser.error("--per-kind must be >= 1")
    paths = make_shape_set(pathlib.Path(args.out_dir), args.per_kind, args.seed)
    print(f"[make_shape_set] wrote {len(paths)} meshes to {args.out_dir}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
