"""seg_merge_train: train the merge classifier (merge_model) on scenes segmented with an oracle.

1. Shards: one seeded cluttered scene per shard (training categories, 4 of 5 in the realistic
   domain; the test split uses the held-out categories), --views camera poses of the paper's
   distribution. Each view is segmented with an oracle in the classifier's place: at every merging
   round it records the features of the touching region pairs whose majority true objects are both
   objects, with whether they are the same one, and merges those that are. Stored in
   <data>/<split>/shard_<seed>.npz; shards that exist are skipped, so a run resumes.
2. Training: a two-layer perceptron (torch, Adam, pairs weighted by the square root of the smaller
   region's pixels) on the train split, or --ensemble such fits (seeds --seed ..) stacked into one
   perceptron that averages their logits; accuracy on the test split; weights, feature
   standardisation and a model card (merge.md) to the checkpoint folder.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import pathlib
import sys
import time

import numpy as np

from arm_core.atomic_io import atomic_write
from arm_segmentation.merge_model import DEFAULT_CHECKPOINT, FEATURE_NAMES, LearnedMerge, MergeClassifier
from arm_segmentation.perceptron import fit_perceptron, perceptron_probability, save_perceptron, stack_perceptrons
from arm_training.segmentation.shards import run_jobs, shard_path

DEFAULT_DATA = pathlib.Path("data/seg_merge")
SPLIT_SEED_OFFSET = {"train": 300_000, "test": 400_000}
PLAIN_EVERY = 5


class OracleMerge(LearnedMerge):
    """LearnedMerge that records the pairs with the truth (same majority object) and merges by the
    truth, or by `policy` (a MergeClassifier) when given: then the recorded regions are those the
    classifier itself produces."""

    def __init__(self, gt_labels, records: list, *args, policy=None):
        super().__init__(policy, *args)
        self.gt, self.records = np.asarray(gt_labels, dtype=np.int64), records

    def start(self, labels: np.ndarray, n: int) -> None:
        super().start(labels, n)
        width = max(int(self.gt.max()), 1) + 1  # a crop may hold no true object: nothing then merges
        hist = np.bincount((labels.astype(np.int64) * width + self.gt).ravel(), minlength=(n + 1) * width)
        self.fragment_hist = hist.reshape(n + 1, width).astype(np.float64)

    def probability(self, owner, pairs, counts):
        region_hist = np.zeros_like(self.fragment_hist)
        np.add.at(region_hist, owner, self.fragment_hist)
        majority = np.argmax(region_hist[:, 1:], axis=1) + 1
        majority[region_hist[:, 0] >= region_hist[:, 1:].max(axis=1)] = 0
        a, b = majority[pairs[:, 0]], majority[pairs[:, 1]]
        known = (a > 0) & (b > 0) & (counts[:, :3].sum(axis=1) >= 3)
        same = a == b
        regions = self._regions(owner)
        smaller = np.minimum(regions["size"][pairs[:, 0]], regions["size"][pairs[:, 1]])
        features = self.features(owner, pairs, counts, regions)
        self.records.append((features[known], same[known], smaller[known]))
        if self.classifier is not None:
            return super().probability(owner, pairs, counts)
        return np.where(known & same, 1.0, 0.0)


def make_shard(seed: int, split: str, views: int, policy: str = "", geometric_merge: bool = True) -> dict:
    """Region-pair features, labels (1 = one object) and smaller-region pixels of one scene's views;
    policy: merge classifier weights that decide the merges ('' = the truth decides);
    geometric_merge: whether the smooth-surface rule merges first (ClusterParams.geometric_merge)."""
    from arm_segmentation.clustering import ClusterParams
    from arm_segmentation.segmentation import SegmentationParams, segment_detailed
    from arm_sim.objects import object_pool
    from arm_sim.views import BenchmarkScene

    rng = np.random.default_rng([SPLIT_SEED_OFFSET[split], seed])
    domain = "plain" if seed % PLAIN_EVERY == PLAIN_EVERY - 1 else "realistic"
    pool = object_pool(split="train" if split == "train" else "heldout", seed=seed)
    records: list = []
    classifier = MergeClassifier(policy) if policy else None
    params = SegmentationParams(cluster=ClusterParams(geometric_merge=geometric_merge))
    with BenchmarkScene(pool, rng, (3, 20), with_visibility=False, domain=domain) as scene:
        for _ in range(views):
            frame = scene.render()

            def oracle(grid, *args, labels=frame.labels):
                return OracleMerge(labels[grid], records, *args, policy=classifier)

            segment_detailed(frame.rgb, frame.depth_m, frame.K, frame.T_world_camera, params, merge_factory=oracle)
    if not records:
        return {"features": np.zeros((0, len(FEATURE_NAMES)), np.float32), "same": np.zeros(0, bool),
                "smaller_px": np.zeros(0, np.float32)}  # fmt: skip
    return {
        "features": np.concatenate([r[0] for r in records]).astype(np.float32),
        "same": np.concatenate([r[1] for r in records]),
        "smaller_px": np.concatenate([r[2] for r in records]).astype(np.float32),
    }


def policy_dir(data_dir, policy: str) -> pathlib.Path:
    """Where the shards made with the classifier `policy` deciding go (keyed to its weights)."""
    digest = hashlib.sha256(pathlib.Path(policy).read_bytes()).hexdigest()[:10]
    return pathlib.Path(data_dir) / f"policy_{digest}"


def _job(job: dict) -> int:
    arrays = make_shard(job["seed"], job["split"], job["views"], job["policy"], job["geometric_merge"])
    atomic_write(pathlib.Path(job["path"]), lambda tmp: np.savez_compressed(tmp, **arrays))
    return len(arrays["same"])


def generate(data_dir, split: str, shards: int, views: int, workers: int, policy: str = "", geometric=True) -> int:
    """Make the missing shards 0 .. shards - 1 of split; returns the number made."""
    paths = {seed: shard_path(data_dir, split, seed) for seed in range(shards)}
    jobs = [
        {"seed": s, "split": split, "views": views, "policy": policy, "geometric_merge": geometric, "path": str(p)}
        for s, p in paths.items()
        if not p.is_file()
    ]
    run_jobs(_job, jobs, workers, f"seg_merge_train shards ({split})")
    return len(jobs)


def load_split(data_dirs, split: str, shards: int):
    """(features, same, weight) of shards 0 .. shards - 1 of split in each of data_dirs."""
    parts = [np.load(shard_path(d, split, seed)) for d in data_dirs for seed in range(shards)]
    features = np.concatenate([p["features"] for p in parts])
    same = np.concatenate([p["same"] for p in parts]).astype(np.float32)
    weight = np.sqrt(np.concatenate([p["smaller_px"] for p in parts]))
    return features, same, weight / max(float(weight.mean()), 1e-6)


def accuracy(classifier_layers, mean, scale, features, same, weight) -> dict:
    """Pair counts and rates of the perceptron on (features, same); a rate over no pairs is None."""
    predicted = perceptron_probability(features, mean, scale, classifier_layers) > 0.5
    truth = same > 0.5

    def share(values, weights=None):
        if len(values) == 0:
            return None
        return round(float(np.average(values, weights=weights)), 4)

    return {
        "pairs": int(len(truth)),
        "share_same": share(truth),
        "accuracy": share(predicted == truth),
        "weighted_accuracy": share(predicted == truth, weight) if len(truth) and np.sum(weight) > 0 else None,
        "false_merge_rate": share(predicted[~truth]),
        "missed_merge_rate": share(~predicted[truth]),
    }


def save(path: pathlib.Path, mean, scale, layers, card: dict) -> None:
    save_perceptron(path, FEATURE_NAMES, mean, scale, layers, "Merge classifier (seg_merge_train)", card)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default=str(DEFAULT_DATA), help="shard root (<data>/<split>/)")
    parser.add_argument("--train-shards", type=int, default=200)
    parser.add_argument("--test-shards", type=int, default=30)
    parser.add_argument("--views", type=int, default=3, help="camera poses per scene")
    parser.add_argument("--workers", type=int, default=1, help="parallel processes for the shards")
    parser.add_argument("--hidden", type=int, default=32)
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--batch", type=int, default=0, help="pairs per training step (0: all pairs)")
    parser.add_argument("--ensemble", type=int, default=1, help="fits (seeds --seed ..) averaged in one perceptron")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--policy", default="", help="also make and train on shards merged by these weights")
    parser.add_argument(
        "--no-geometric-merge", action="store_true", help="make shards without the smooth-surface merge rule first"
    )
    parser.add_argument("--out", default=str(DEFAULT_CHECKPOINT), help="weights file (.npz)")
    args = parser.parse_args(argv)
    if min(args.train_shards, args.views, args.workers, args.hidden, args.steps, args.ensemble) < 1:
        parser.error("--train-shards, --views, --workers, --hidden, --steps and --ensemble must be >= 1")
    if args.test_shards < 0 or args.batch < 0:
        parser.error("--test-shards and --batch must be >= 0")
    if args.policy and not pathlib.Path(args.policy).is_file():
        parser.error(f"--policy: no such file {args.policy}")
    start = time.perf_counter()
    data_dirs = [pathlib.Path(args.data)] + ([policy_dir(args.data, args.policy)] if args.policy else [])
    made = 0
    for data_dir, policy in zip(data_dirs, ["", args.policy], strict=False):
        geometric = not args.no_geometric_merge
        made += generate(data_dir, "train", args.train_shards, args.views, args.workers, policy, geometric)
        made += generate(data_dir, "test", args.test_shards, args.views, args.workers, policy, geometric)
    features, same, weight = load_split(data_dirs, "train", args.train_shards)
    fits = [
        fit_perceptron(features, same, weight, args.hidden, args.steps, seed, args.batch, f"seg_merge_train fit {seed}")
        for seed in range(args.seed, args.seed + args.ensemble)
    ]
    mean, scale = fits[0][:2]  # the standardisation depends on the data only
    layers = stack_perceptrons([fit[2] for fit in fits]) if len(fits) > 1 else fits[0][2]
    card = {
        "command": "seg_merge_train " + " ".join(sys.argv[1:] if argv is None else argv),
        "features": list(FEATURE_NAMES),
        "train": accuracy(layers, mean, scale, features, same, weight),
        "settings": {k: v for k, v in vars(args).items() if k != "out"},
    }
    if args.test_shards:
        card["test"] = accuracy(layers, mean, scale, *load_split(data_dirs, "test", args.test_shards))
    save(pathlib.Path(args.out), mean, scale, layers, card)
    print(json.dumps({"shards_made": made, "seconds": round(time.perf_counter() - start, 1), **card}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
