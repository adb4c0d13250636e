"""seg_datagen: training frames for the boundary network, rendered by the benchmarks' scene renderer.

Each shard is one seeded cluttered scene of the training categories (3-20 objects; 4 of 5 scenes in
the realistic visual domain, 1 in the plain one) seen from --views random camera poses of the
paper's distribution, with depth noise. Per view it stores the working-grid images the segmentation
computes before clustering (colour, smoothed depth, normals, height above the support) and the
true instance labels: <out>/<split>/shard_<seed>.npz. Shards that exist are skipped, so a run
resumes; the test split uses the held-out categories.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import time

import numpy as np

from arm_core.atomic_io import atomic_write
from arm_core.frames import validate_frame
from arm_training.segmentation.shards import run_jobs, shard_path

DEFAULT_OUT = pathlib.Path("data/seg_boundary")
SPLIT_SEED_OFFSET = {"train": 100_000, "test": 200_000}
PLAIN_EVERY = 5  # every 5th scene is rendered in the plain domain


def make_shard(seed: int, split: str, views: int) -> dict[str, np.ndarray]:
    """The arrays of one shard (see the module docstring)."""
    from arm_segmentation.segmentation import SegmentationParams, working_stage
    from arm_sim.objects import object_pool
    from arm_sim.views import BenchmarkScene

    params = SegmentationParams()
    stride = params.working_stride
    rng = np.random.default_rng([SPLIT_SEED_OFFSET[split], seed])
    domain = "plain" if seed % PLAIN_EVERY == PLAIN_EVERY - 1 else "realistic"
    pool = object_pool(split="train" if split == "train" else "heldout", seed=seed)
    columns: dict[str, list] = {"rgb": [], "depth": [], "normals": [], "height": [], "labels": []}
    with BenchmarkScene(pool, rng, (3, 20), with_visibility=False, domain=domain) as scene:
        for _ in range(views):
            frame = scene.render()
            valid = validate_frame(frame.depth_m, frame.K, frame.T_world_camera, rgb=frame.rgb)
            rgb, _, _, stage = working_stage(valid.rgb, valid.depth_m, valid.K, valid.T_world_camera, params)
            columns["rgb"].append(rgb)
            columns["depth"].append(stage.smoothed.astype(np.float16))
            columns["normals"].append(np.round(stage.normals_camera * 127).astype(np.int8))
            columns["height"].append((stage.points_world[..., 2] - stage.support).astype(np.float16))
            columns["labels"].append(frame.labels[::stride, ::stride].astype(np.uint16))
    arrays = {name: np.stack(values) for name, values in columns.items()}
    arrays["domain"] = np.array(domain)
    return arrays


def _job(job: dict) -> int:
    arrays = make_shard(job["seed"], job["split"], job["views"])
    atomic_write(pathlib.Path(job["path"]), lambda tmp: np.savez_compressed(tmp, **arrays))
    return len(arrays["rgb"])


def generate(out_dir, split: str, shards: int, first_seed: int, views: int, workers: int) -> dict:
    """Make the missing shards first_seed .. first_seed + shards - 1; returns counts and timing."""
    jobs = [
        {"seed": seed, "split": split, "views": views, "path": str(shard_path(out_dir, split, seed))}
        for seed in range(first_seed, first_seed + shards)
        if not shard_path(out_dir, split, seed).is_file()
    ]
    start = time.perf_counter()
    frames = run_jobs(_job, jobs, workers, f"seg_datagen {split}")
    elapsed = time.perf_counter() - start
    return {"shards_made": len(jobs), "frames_made": frames, "seconds": round(elapsed, 1)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=str(DEFAULT_OUT), help="dataset root (shards go to <out>/<split>/)")
    parser.add_argument("--split", choices=sorted(SPLIT_SEED_OFFSET), default="train")
    parser.add_argument("--shards", type=int, default=100, help="number of shards (one scene each)")
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--views", type=int, default=6, help="camera poses per scene")
    parser.add_argument("--workers", type=int, default=1, help="parallel processes")
    args = parser.parse_args(argv)
    if args.shards < 0 or args.views < 1 or args.workers < 1:
        parser.error("--shards must be >= 0, --views and --workers >= 1")
    print(json.dumps(generate(args.out, args.split, args.shards, args.first_seed, args.views, args.workers)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
