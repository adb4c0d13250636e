"""seg_outline_train: train the outline classifier (outline_model) against the true masks.

1. Shards: one seeded cluttered scene per shard (training categories, 4 of 5 in the realistic
   domain; the test split uses the held-out categories), --views camera poses of the paper's
   distribution, each segmented by the default method without the outline pass. Per view the
   features of the pixels near the outlines, and whether each pixel belongs to the true object the
   nearest instance mostly covers: <data>/<split>/shard_<seed>.npz. Shards that exist are kept,
   so a run resumes.
2. Training: a two-layer perceptron (torch, Adam on random minibatches) on the train split;
   accuracy on the test split beside the colour rule's (boundary.refine_borders); weights,
   feature standardisation and a model card (outline.md) to the checkpoint folder.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
import time
from dataclasses import replace

import numpy as np

from arm_core.atomic_io import atomic_write
from arm_core.frames import validate_frame
from arm_segmentation.boundary import OutlineBand, outline_band
from arm_segmentation.outline_model import (
    DEFAULT_CHECKPOINT,
    FEATURE_NAMES,
    OutlineParams,
    outline_features,
    outline_image,
)
from arm_segmentation.perceptron import fit_perceptron, perceptron_probability, save_perceptron
from arm_training.segmentation.shards import run_jobs, shard_path

DEFAULT_DATA = pathlib.Path("data/seg_outline")
SPLIT_SEED_OFFSET = {"train": 500_000, "test": 600_000}
PLAIN_EVERY = 5


def belongs(labels: np.ndarray, truth: np.ndarray, band: OutlineBand) -> np.ndarray:
    """(P,) bool: each band pixel lies on the true object that its candidate instance mostly covers."""
    labels, truth = labels.astype(np.int64), truth.astype(np.int64)
    n, width = int(labels.max()) + 1, int(truth.max()) + 1
    hist = np.bincount((labels * width + truth).ravel(), minlength=n * width).reshape(n, width)
    majority = np.argmax(hist[:, 1:], axis=1) + 1 if width > 1 else np.zeros(n, np.int64)
    if width > 1:
        majority[hist[:, 1:].max(axis=1) == 0] = -1
    on = truth[band.rows, band.cols]
    return (on > 0) & (majority[band.candidate] == on)


def make_shard(seed: int, split: str, views: int) -> dict[str, np.ndarray]:
    """Band-pixel features and truth of one scene's views (see the module docstring)."""
    from arm_segmentation.segmentation import SegmentationParams, segment_detailed
    from arm_sim.objects import object_pool
    from arm_sim.views import BenchmarkScene

    rng = np.random.default_rng([SPLIT_SEED_OFFSET[split], seed])
    domain = "plain" if seed % PLAIN_EVERY == PLAIN_EVERY - 1 else "realistic"
    pool = object_pool(split="train" if split == "train" else "heldout", seed=seed)
    pass_params = OutlineParams()
    params = replace(SegmentationParams(), outline=replace(pass_params, enabled=False))
    features, truth = [np.zeros((0, len(FEATURE_NAMES)), np.float32)], [np.zeros(0, bool)]
    with BenchmarkScene(pool, rng, (3, 20), with_visibility=False, domain=domain) as scene:
        for _ in range(views):
            frame = scene.render()
            result = segment_detailed(frame.rgb, frame.depth_m, frame.K, frame.T_world_camera, params)
            band = outline_band(result.labels, pass_params.band_px)
            if band is None or result.objectness is None:
                continue
            depth = validate_frame(frame.depth_m, frame.K, frame.T_world_camera, rgb=frame.rgb).depth_m
            image = outline_image(frame.rgb, depth, result.objectness, pass_params.blur_px)
            features.append(outline_features(result.labels, image, band))
            truth.append(belongs(result.labels, frame.labels, band))
    return {"features": np.concatenate(features).astype(np.float16), "belongs": np.concatenate(truth)}


def _job(job: dict) -> int:
    arrays = make_shard(job["seed"], job["split"], job["views"])
    atomic_write(pathlib.Path(job["path"]), lambda tmp: np.savez_compressed(tmp, **arrays))
    return len(arrays["belongs"])


def generate(data_dir, split: str, shards: int, views: int, workers: int) -> int:
    """Make the missing shards 0 .. shards - 1 of split; returns the number made."""
    jobs = [
        {"seed": seed, "split": split, "views": views, "path": str(shard_path(data_dir, split, seed))}
        for seed in range(shards)
        if not shard_path(data_dir, split, seed).is_file()
    ]
    run_jobs(_job, jobs, workers, f"seg_outline_train shards ({split})")
    return len(jobs)


def load_split(data_dir, split: str, shards: int) -> tuple[np.ndarray, np.ndarray]:
    """(features, belongs) of shards 0 .. shards - 1 of split."""
    parts = [np.load(shard_path(data_dir, split, seed)) for seed in range(shards)]
    features = np.concatenate([p["features"] for p in parts]).astype(np.float32)
    return features, np.concatenate([p["belongs"] for p in parts])


def accuracy(layers, mean, scale, features, belongs_truth) -> dict:
    """Pixel counts and accuracies of the perceptron and of the colour rule on (features, truth)."""
    if len(belongs_truth) == 0:
        return {"pixels": 0}
    predicted = perceptron_probability(features, mean, scale, layers) > 0.5
    colour_rule = features[:, FEATURE_NAMES.index("to_inside")] < features[:, FEATURE_NAMES.index("to_outside")]
    return {
        "pixels": int(len(belongs_truth)),
        "share_object": round(float(np.mean(belongs_truth)), 4),
        "accuracy": round(float(np.mean(predicted == belongs_truth)), 4),
        "colour_rule_accuracy": round(float(np.mean(colour_rule == belongs_truth)), 4),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default=str(DEFAULT_DATA), help="shard root (<data>/<split>/)")
    parser.add_argument("--train-shards", type=int, default=200)
    parser.add_argument("--test-shards", type=int, default=20)
    parser.add_argument("--views", type=int, default=3, help="camera poses per scene")
    parser.add_argument("--workers", type=int, default=1, help="parallel processes for the shards")
    parser.add_argument("--hidden", type=int, default=32)
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--batch", type=int, default=8192, help="pixels per training step")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=str(DEFAULT_CHECKPOINT), help="weights file (.npz)")
    args = parser.parse_args(argv)
    if min(args.train_shards, args.views, args.workers, args.hidden, args.steps, args.batch) < 1:
        parser.error("--train-shards, --views, --workers, --hidden, --steps and --batch must be >= 1")
    if args.test_shards < 0:
        parser.error("--test-shards must be >= 0")
    start = time.perf_counter()
    made = generate(args.data, "train", args.train_shards, args.views, args.workers)
    made += generate(args.data, "test", args.test_shards, args.views, args.workers)
    features, truth = load_split(args.data, "train", args.train_shards)
    if len(truth) == 0:
        print(f"seg_outline_train: no outline pixels in {args.train_shards} training shards", file=sys.stderr)
        return 1
    weight = np.ones(len(truth), np.float32)
    fit = fit_perceptron(features, truth, weight, args.hidden, args.steps, args.seed, args.batch, "seg_outline_train")
    mean, scale, layers = fit
    card = {
        "command": "seg_outline_train " + " ".join(sys.argv[1:] if argv is None else argv),
        "features": list(FEATURE_NAMES),
        "train": accuracy(layers, mean, scale, features, truth),
        "settings": {k: v for k, v in vars(args).items() if k != "out"},
    }
    if args.test_shards:
        card["test"] = accuracy(layers, mean, scale, *load_split(args.data, "test", args.test_shards))
    save_perceptron(pathlib.Path(args.out), FEATURE_NAMES, mean, scale, layers, "Outline classifier", card)
    print(json.dumps({"shards_made": made, "seconds": round(time.perf_counter() - start, 1), **card}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
