import numpy as np
import pytest

from arm_segmentation.clustering import ClusterParams, merge_fragments
from arm_segmentation.merge_model import (
    FEATURE_NAMES,
    LearnedMerge,
    MergeClassifier,
    pixel_statistics,
    region_pair_features,
)
from arm_training.segmentation.merge_train import OracleMerge, save


def _three_fragments():
    """Fragments A | B | C side by side on one flat surface; A and B one true object, C another."""
    labels = np.repeat(np.arange(1, 4), 10)[None, :].repeat(10, axis=0)
    truth = np.where(labels < 3, 1, 2)
    rgb = np.full((10, 30, 3), 120, dtype=np.uint8)
    rgb[:, 20:] = (60, 160, 90)
    chroma = (rgb - rgb.mean(axis=-1, keepdims=True)) / 255.0
    normals = np.zeros((10, 30, 3))
    normals[..., 2] = -1.0
    area = np.full((10, 30), 1e-4)
    stats = pixel_statistics(chroma, rgb, normals, area)
    height = np.full((10, 30), 0.05)
    height[:, ::10] = 0.0  # every fragment reaches its support
    return labels, truth, chroma.astype(np.float32), stats, height, area


def test_pair_features_do_not_depend_on_the_order_of_the_pair():
    labels, _, _, stats, height, _ = _three_fragments()
    merge = LearnedMerge(None, stats, height, np.zeros(labels.shape), ClusterParams())
    merge.start(labels, 3)
    owner = np.arange(4)
    counts = np.array([[20.0, 0.0, 0.0, 18.0, 2.0]])
    forward = merge.features(owner, np.array([[1, 3]]), counts)
    backward = merge.features(owner, np.array([[3, 1]]), counts)
    assert forward.shape == (1, len(FEATURE_NAMES)) and np.allclose(forward, backward)
    names = dict(zip(FEATURE_NAMES, forward[0], strict=True))
    assert names["chroma_distance"] > 0.2 and names["continuous_share"] == 1.0
    assert names["low_small_m"] == pytest.approx(0.0) and names["normal_cosine"] == pytest.approx(1.0)
    assert region_pair_features(np.zeros((0, 2), int), np.zeros((0, 5)), merge.sums, merge.size, merge.low,
                                merge.high, 2).shape == (0, len(FEATURE_NAMES))  # fmt: skip


def test_oracle_merging_joins_one_object_and_records_the_pairs():
    labels, truth, chroma, stats, height, area = _three_fragments()
    depth = np.full(labels.shape, 0.8, dtype=np.float32)
    records: list = []
    oracle = OracleMerge(truth, records, stats, height, np.zeros(labels.shape), ClusterParams())
    merged = merge_fragments(labels, 3, depth, chroma, area, ClusterParams(), scorer=oracle)
    assert len(np.unique(merged[:, :20])) == 1 and np.all(merged[:, 20:] != merged[0, 0])
    features, same, smaller = records[0]
    assert features.shape == (2, len(FEATURE_NAMES)) and sorted(same.tolist()) == [False, True]
    assert np.all(smaller == 100)


def test_oracle_merges_nothing_where_no_true_object_is_in_view():
    labels, truth, chroma, stats, height, area = _three_fragments()
    depth = np.full(labels.shape, 0.8, dtype=np.float32)
    records: list = []
    oracle = OracleMerge(np.zeros_like(truth), records, stats, height, np.zeros(labels.shape), ClusterParams())
    merged = merge_fragments(labels, 3, depth, chroma, area, ClusterParams(), scorer=oracle)
    assert len(np.unique(merged)) == 3 and records[0][0].shape[0] == 0


def test_classifier_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    n = len(FEATURE_NAMES)
    layers = [(rng.normal(size=(n, 4)).astype(np.float32), np.zeros(4, np.float32)),
              (rng.normal(size=(4, 1)).astype(np.float32), np.zeros(1, np.float32))]  # fmt: skip
    path = tmp_path / "merge.npz"
    save(path, np.zeros(n, np.float32), np.ones(n, np.float32), layers, {"note": "test"})
    classifier = MergeClassifier(path)
    features = rng.normal(size=(7, n)).astype(np.float32)
    expected = 1.0 / (1.0 + np.exp(-(np.maximum(features @ layers[0][0], 0.0) @ layers[1][0])[:, 0]))
    assert np.allclose(classifier.probability(features), expected, atol=1e-5)
    assert (tmp_path / "merge.md").read_text().startswith("# Merge classifier")


def test_seg_merge_train_makes_shards_trains_and_resumes(tmp_path):
    from arm_training.segmentation.merge_train import main

    out = tmp_path / "merge.npz"
    args = ["--data", str(tmp_path / "data"), "--train-shards", "1", "--test-shards", "1", "--views", "1"]
    args += ["--steps", "5", "--hidden", "4", "--out", str(out)]
    assert main(args) == 0
    shards = sorted(p.name for p in (tmp_path / "data").rglob("*.npz"))
    assert shards == ["shard_000000.npz", "shard_000000.npz"]
    classifier = MergeClassifier(out)
    assert len(classifier.layers) == 3 and classifier.layers[0][0].shape == (len(FEATURE_NAMES), 4)
    stamp = (tmp_path / "data" / "train" / "shard_000000.npz").stat().st_mtime_ns
    ensemble = tmp_path / "ensemble.npz"
    second = [*args[:-1], str(ensemble), "--policy", str(out), "--ensemble", "2", "--batch", "16"]
    assert main(second) == 0  # the oracle's shards are kept, the policy's made
    assert (tmp_path / "data" / "train" / "shard_000000.npz").stat().st_mtime_ns == stamp
    assert len(list((tmp_path / "data").glob("policy_*/train/shard_000000.npz"))) == 1
    members = MergeClassifier(ensemble).layers
    assert [w.shape for w, _ in members] == [(2, len(FEATURE_NAMES), 4), (2, 4, 4), (2, 4, 1)]
