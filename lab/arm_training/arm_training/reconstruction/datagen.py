"""Training / test data for the reconstruction network (paper appendix "Cluttered Reconstruction
Benchmark Details").

One shard per seed: ``scenes_per_shard`` cluttered scenes dropped from the split's procedural
categories (train: arm_sim TRAIN_CATEGORIES, test: HELDOUT_CATEGORIES) and settled by physics,
``views_per_scene`` random camera views of each (noisy depth), and one sample per object that shows
at least ``min_visible_pixels`` pixels with depth: its four-channel grid (input), the ground-truth
occupancy of its watertight mesh at its settled pose in the same grid, the other objects'
ground-truth occupancy (the stability prior's support term), its visible fraction and metadata.
Grids are bit-packed (``np.packbits``) in a compressed ``.npz`` written atomically as
``<out>/<split>/shard_<seed>.npz``; finished shards are skipped, so runs resume after an interruption
and shards can be produced by many processes or machines and merged by copying the files.
``manifest.json`` lists every shard with its sample count and sha256.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import pathlib
import time
from concurrent.futures import ProcessPoolExecutor, as_completed

import numpy as np
from tqdm import tqdm

from arm_core.atomic_io import atomic_write, atomic_write_json
from arm_reconstruction.grid import DEFAULT_K, frame_grids, voxelize_mesh
from arm_sim.appearance import DEFAULT_DOMAIN, DOMAINS
from arm_sim.objects import object_pool
from arm_sim.views import BenchmarkScene

FORMAT = "arm-voxel-shard-v1"
SPLIT_SEED_OFFSET = {"train": 0, "test": 1_000_000}
SPLIT_OBJECT_POOL = {"train": "train", "test": "heldout"}
DEFAULT_OUT = pathlib.Path("data/arm_dataset")
MIN_VISIBLE_PIXELS = 50


def shard_path(out_dir, split: str, seed: int) -> pathlib.Path:
    return pathlib.Path(out_dir) / split / f"shard_{seed:07d}.npz"


def pack_bits(array: np.ndarray) -> np.ndarray:
    """``[n, ...]`` 0/1 array -> ``[n, ceil(size / 8)]`` uint8 (big-endian bit order)."""
    flat = np.asarray(array).reshape(len(array), -1) > 0.5
    return np.packbits(flat, axis=1)


def _voxelize_overlapping(meshes, bounds, frame) -> np.ndarray:
    """Union of the voxelized meshes whose bounding boxes overlap the grid, bool [d, d, d]."""
    lo = np.asarray(frame.origin_world)
    hi = lo + frame.side_m
    occupancy = np.zeros((frame.resolution,) * 3, dtype=bool)
    for mesh, (mesh_lo, mesh_hi) in zip(meshes, bounds, strict=True):
        if np.all(mesh_hi >= lo) and np.all(mesh_lo <= hi):
            occupancy |= voxelize_mesh(mesh, frame)
    return occupancy


def generate_shard(
    seed: int,
    split: str = "train",
    resolution: int = 32,
    k: float = DEFAULT_K,
    scenes_per_shard: int = 1,
    views_per_scene: int = 8,
    min_visible_pixels: int = MIN_VISIBLE_PIXELS,
    objects_per_scene: tuple[int, int] = (3, 20),
    domain: str = DEFAULT_DOMAIN,
) -> dict[str, np.ndarray]:
    """All samples of one shard as arrays (see module doc). Deterministic for a (split, seed)."""
    rng = np.random.default_rng([SPLIT_SEED_OFFSET[split], int(seed)])
    pool = object_pool(split=SPLIT_OBJECT_POOL[split])
    columns: dict[str, list] = {key: [] for key in _SAMPLE_KEYS}
    for scene_index in range(scenes_per_shard):
        with BenchmarkScene(pool, rng, tuple(objects_per_scene), domain=domain) as views:
            scene = views.scene
            meshes = [placed.world_mesh() for placed in scene.objects]
            bounds = [mesh.bounds for mesh in meshes]
            for view_index in range(views_per_scene):
                frame = views.render()
                pixels = np.bincount(frame.labels[frame.depth_m > 0].ravel(), minlength=len(scene.objects) + 1)[1:]
                visible_ids = [int(i) + 1 for i in np.flatnonzero(pixels >= min_visible_pixels)]
                if not visible_ids:
                    continue
                grids = frame_grids(
                    frame.depth_m, frame.K, frame.T_world_camera, frame.labels, visible_ids, resolution, k
                )
                for grid, grid_frame, object_id in zip(grids.grids, grids.frames, grids.object_ids, strict=True):
                    index = object_id - 1
                    others = [j for j in range(len(meshes)) if j != index]
                    columns["grids"].append(grid > 0.5)
                    columns["occupancy"].append(voxelize_mesh(meshes[index], grid_frame))
                    columns["others"].append(
                        _voxelize_overlapping([meshes[j] for j in others], [bounds[j] for j in others], grid_frame)
                    )
                    columns["visible_fraction"].append(frame.visible_fraction[index])
                    columns["visible_pixels"].append(pixels[index])
                    columns["category"].append(scene.objects[index].model.category)
                    columns["object_scale"].append(scene.objects[index].scale)
                    columns["scene_index"].append(scene_index)
                    columns["view_index"].append(view_index)
                    columns["object_index"].append(index)
                    columns["grid_origin_world"].append(grid_frame.origin_world)
                    columns["voxel_size_m"].append(grid_frame.voxel_size_m)
                    columns["table_height_m"].append(grid_frame.table_height_m)
                    columns["T_world_camera"].append(frame.T_world_camera)
    return _to_arrays(columns, seed, split, resolution, k, domain)


_SAMPLE_KEYS = (
    "grids",
    "occupancy",
    "others",
    "visible_fraction",
    "visible_pixels",
    "category",
    "object_scale",
    "scene_index",
    "view_index",
    "object_index",
    "grid_origin_world",
    "voxel_size_m",
    "table_height_m",
    "T_world_camera",
)


def _to_arrays(columns, seed, split, resolution, k, domain) -> dict[str, np.ndarray]:
    d = int(resolution)
    n = len(columns["grids"])
    grids = np.stack(columns["grids"]) if n else np.zeros((0, 4, d, d, d), bool)
    occupancy = np.stack(columns["occupancy"]) if n else np.zeros((0, d, d, d), bool)
    others = np.stack(columns["others"]) if n else np.zeros((0, d, d, d), bool)
    return {
        "format": np.array(FORMAT),
        "split": np.array(split),
        "seed": np.array(int(seed)),
        "resolution": np.array(d),
        "k": np.array(float(k)),
        "domain": np.array(domain),
        "grids_bits": pack_bits(grids),
        "occupancy_bits": pack_bits(occupancy),
        "others_bits": pack_bits(others),
        "visible_fraction": np.asarray(columns["visible_fraction"], np.float32),
        "visible_pixels": np.asarray(columns["visible_pixels"], np.int32),
        "category": np.asarray(columns["category"], dtype="<U32"),
        "object_scale": np.asarray(columns["object_scale"], np.float32),
        "scene_index": np.asarray(columns["scene_index"], np.int16),
        "view_index": np.asarray(columns["view_index"], np.int16),
        "object_index": np.asarray(columns["object_index"], np.int16),
        "grid_origin_world": np.asarray(columns["grid_origin_world"], np.float64).reshape(n, 3),
        "voxel_size_m": np.asarray(columns["voxel_size_m"], np.float64),
        "table_height_m": np.asarray(columns["table_height_m"], np.float64),
        "T_world_camera": np.asarray(columns["T_world_camera"], np.float64).reshape(n, 4, 4),
    }


def write_shard(path, arrays: dict[str, np.ndarray]) -> str:
    """Atomic compressed write; returns the file's sha256."""
    return file_sha256(atomic_write(path, lambda tmp: np.savez_compressed(tmp, **arrays)))


def file_sha256(path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def shard_sample_count(path) -> int | None:
    """Samples in a finished shard, or None when the file is missing or unreadable."""
    try:
        with np.load(path, allow_pickle=False) as shard:
            if str(shard["format"]) != FORMAT:
                return None
            return int(len(shard["visible_fraction"]))
    except (OSError, ValueError, KeyError, EOFError):
        return None


def _make_shard(job: dict) -> tuple[int, int, float]:
    start = time.perf_counter()
    arrays = generate_shard(**job["settings"], seed=job["seed"], split=job["split"])
    write_shard(job["path"], arrays)
    return job["seed"], len(arrays["visible_fraction"]), time.perf_counter() - start


def write_manifest(out_dir, split: str, settings: dict) -> dict:
    """Scan the split's shards and write ``<out>/<split>/manifest.json`` (counts and sha256)."""
    folder = pathlib.Path(out_dir) / split
    shards = []
    for path in sorted(folder.glob("shard_*.npz")):
        count = shard_sample_count(path)
        if count is not None:
            shards.append({"file": path.name, "samples": count, "sha256": file_sha256(path)})
    manifest = {
        "format": FORMAT,
        "split": split,
        "object_pool": SPLIT_OBJECT_POOL[split],
        "settings": settings,
        "n_shards": len(shards),
        "n_samples": int(sum(s["samples"] for s in shards)),
        "shards": shards,
    }
    atomic_write_json(folder / "manifest.json", manifest, indent=1)
    return manifest


def generate(
    out_dir=DEFAULT_OUT,
    split: str = "train",
    n_shards: int = 10,
    first_seed: int = 0,
    workers: int = 1,
    progress: bool = True,
    **settings,
) -> dict:
    """Produce the missing shards ``first_seed .. first_seed + n_shards - 1`` and the manifest.

    Returns a summary with ``samples_per_s`` over the shards made in this call."""
    if split not in SPLIT_SEED_OFFSET:
        raise ValueError(f"split must be one of {sorted(SPLIT_SEED_OFFSET)}, got {split!r}")
    jobs = []
    for seed in range(first_seed, first_seed + n_shards):
        path = shard_path(out_dir, split, seed)
        if shard_sample_count(path) is None:
            jobs.append({"seed": seed, "split": split, "path": str(path), "settings": settings})
    made, samples, start = 0, 0, time.perf_counter()
    bar = tqdm(total=len(jobs), desc=f"datagen {split}", unit="shard", disable=not progress)
    if workers <= 1:
        for job in jobs:
            _, count, _ = _make_shard(job)
            made, samples = made + 1, samples + count
            bar.update(1)
            bar.set_postfix(samples=samples)
    else:
        with ProcessPoolExecutor(max_workers=workers) as executor:
            for future in as_completed([executor.submit(_make_shard, job) for job in jobs]):
                _, count, _ = future.result()
                made, samples = made + 1, samples + count
                bar.update(1)
                bar.set_postfix(samples=samples)
    bar.close()
    elapsed = time.perf_counter() - start
    manifest = write_manifest(out_dir, split, dict(settings, first_seed=first_seed))
    return {
        "shards_made": made,
        "samples_made": samples,
        "seconds": elapsed,
        "samples_per_s": samples / elapsed if made and elapsed > 0 else None,
        "n_shards": manifest["n_shards"],
        "n_samples": manifest["n_samples"],
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=str(DEFAULT_OUT), help="dataset root (shards go to <out>/<split>/)")
    parser.add_argument(
        "--split",
        choices=sorted(SPLIT_SEED_OFFSET),
        default="train",
        help="train: training categories; test: held-out categories",
    )
    parser.add_argument("--shards", type=int, default=10, help="number of shards (one seed each)")
    parser.add_argument("--first-seed", type=int, default=0, help="seed of the first shard")
    parser.add_argument("--workers", type=int, default=1, help="parallel processes")
    parser.add_argument("--scenes-per-shard", type=int, default=1)
    parser.add_argument("--views-per-scene", type=int, default=8)
    parser.add_argument("--resolution", type=int, default=32, help="grid side in voxels")
    parser.add_argument("--k", type=float, default=DEFAULT_K, help="grid side / observed object diameter")
    parser.add_argument("--min-visible-pixels", type=int, default=MIN_VISIBLE_PIXELS)
    parser.add_argument("--domain", choices=DOMAINS, default=DEFAULT_DOMAIN, help="visual domain of the scenes")
    args = parser.parse_args(argv)
    if args.shards < 0 or args.workers < 1 or args.views_per_scene < 1 or args.scenes_per_shard < 1:
        parser.error("--shards must be >= 0, --workers, --views-per-scene and --scenes-per-shard >= 1")
    summary = generate(
        args.out,
        args.split,
        args.shards,
        args.first_seed,
        args.workers,
        resolution=args.resolution,
        k=args.k,
        scenes_per_shard=args.scenes_per_shard,
        views_per_scene=args.views_per_scene,
        min_visible_pixels=args.min_visible_pixels,
        domain=args.domain,
    )
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
