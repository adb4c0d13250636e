"""The floor a voxel grid sets on reconstruction error: bench_recon's scenes and views, every evaluated
object's TRUE occupancy voxelized in its grid (side k x the observed diameter, d^3 voxels), meshed by
the pipeline's meshing and scored against the true mesh: the error of a perfect network on that grid
before depth snapping. This is how the grid's k and resolution were chosen.

    python -m arm_benchmarks.grid_floor --seed 0 --scenes 6 [--grids 4:32 2:32 ...] [--out DIR]

Per grid: mean and median Chamfer (mm), mean voxel size (mm), and the share of objects whose true
occupancy reaches a side or the top of the grid (cut off by it). Writes OUT/summary.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import pathlib

import numpy as np
from tqdm import tqdm

from arm_benchmarks.recon.config import BenchConfig
from arm_benchmarks.recon.scenes import evaluated_ids, render_scene
from arm_benchmarks.stats import median
from arm_core.atomic_io import atomic_write_json
from arm_reconstruction.grid import frame_grids, voxelize_mesh
from arm_reconstruction.meshing import occupancy_mesh
from arm_reconstruction.metrics import chamfer_distance_m, normal_consistency
from arm_sim.objects import object_pool

DEFAULT_GRIDS = ("4:32", "3:32", "2.5:32", "2:32", "3:48")


def parse_grid(text: str) -> tuple[float, int]:
    """'K:D' -> (k, resolution)."""
    k, resolution = text.split(":")
    return float(k), int(resolution)


def reaches_grid_boundary(occupancy: np.ndarray) -> bool:
    """True occupancy in a side layer or the top layer of the grid (the bottom is the table)."""
    return bool(
        occupancy[0].any()
        or occupancy[-1].any()
        or occupancy[:, 0].any()
        or occupancy[:, -1].any()
        or occupancy[:, :, -1].any()
    )


def scene_floor(index: int, config: BenchConfig, pool, grids) -> dict[str, list]:
    """Per grid 'k:d': rows (chamfer_m, voxel_size_m, cut, normal consistency) of every evaluated
    object of scene `index`."""
    scene, frame = render_scene(index, config, pool)
    ids = evaluated_ids(frame.labels, frame.depth_m, config.min_visible_pixels)
    meshes = {i: scene.objects[i - 1].world_mesh() for i in ids}
    rows: dict[str, list] = {}
    for k, resolution in grids:
        built = frame_grids(frame.depth_m, frame.K, frame.T_world_camera, frame.labels, ids, resolution, k)
        key = f"{k:g}:{resolution}"
        rows[key] = []
        for grid_frame, object_id in zip(built.frames, built.object_ids, strict=True):
            occupancy = voxelize_mesh(meshes[object_id], grid_frame)
            if not occupancy.any():
                rows[key].append((None, grid_frame.voxel_size_m, True, None))
                continue
            mesh = occupancy_mesh(
                occupancy.astype(np.float32), grid_frame, smoothing_iterations=config.smoothing_iterations
            )
            chamfer = chamfer_distance_m(mesh, meshes[object_id], config.chamfer_samples)
            normals = normal_consistency(mesh, meshes[object_id], config.chamfer_samples)
            rows[key].append((chamfer, grid_frame.voxel_size_m, reaches_grid_boundary(occupancy), normals))
    return rows


def summarize(rows: dict[str, list]) -> dict[str, dict]:
    summary = {}
    for key, values in rows.items():
        chamfers = [c for c, _, _, _ in values if c is not None]
        summary[key] = {
            "objects": len(values),
            "chamfer_mm_mean": 1000 * float(np.mean(chamfers)) if chamfers else None,
            "chamfer_mm_median": 1000 * median(chamfers) if chamfers else None,
            "normal_consistency": float(np.mean([n for *_, n in values if n is not None])) if chamfers else None,
            "voxel_mm_mean": 1000 * float(np.mean([v for _, v, _, _ in values])),
            "cut_fraction": float(np.mean([cut for _, _, cut, _ in values])),
            "empty": sum(c is None for c, *_ in values),
        }
    return summary


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--scenes", type=int, default=6)
    parser.add_argument("--domain", default=BenchConfig.domain)
    parser.add_argument("--grids", nargs="+", default=list(DEFAULT_GRIDS), help="K:D pairs")
    parser.add_argument("--smoothing-iterations", type=int, default=BenchConfig.smoothing_iterations)
    parser.add_argument("--out", default="")
    args = parser.parse_args(argv)
    grids = [parse_grid(text) for text in args.grids]
    config = BenchConfig(
        scenes=args.scenes, seed=args.seed, domain=args.domain, smoothing_iterations=args.smoothing_iterations
    )
    pool = object_pool(None, split="heldout", seed=config.seed)
    rows: dict[str, list] = {}
    for index in tqdm(range(args.scenes), desc="grid floor", unit="scene"):
        for key, values in scene_floor(index, config, pool, grids).items():
            rows.setdefault(key, []).extend(values)
    summary = {"config": dataclasses.asdict(config) | {"grids": args.grids}, "grids": summarize(rows)}
    out = pathlib.Path(args.out or f"results/grid_floor_seed{args.seed}")
    atomic_write_json(out / "summary.json", summary)
    for key, figures in summary["grids"].items():
        print(
            f"k:d {key:>7}  Chamfer {figures['chamfer_mm_mean']:.2f} mm (median {figures['chamfer_mm_median']:.2f})"
            f"  normals {figures['normal_consistency']:.3f}  voxel {figures['voxel_mm_mean']:.1f} mm"
            f"  cut {figures['cut_fraction']:.3f}  ({figures['objects']})"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
