"""Data generation and training of the segmentation's boundary network and outline classifier, end
to end on a few simulated views."""

import numpy as np
import torch

from arm_segmentation.boundary import outline_band
from arm_segmentation.boundary_net import FEATURE_CHANNELS, BoundaryPredictor, boundary_features
from arm_segmentation.outline_model import FEATURE_NAMES, OutlineClassifier
from arm_training.segmentation.boundary_data import make_shard
from arm_training.segmentation.boundary_train import NORMAL_X_CHANNEL, crop_batch, frame_arrays
from arm_training.segmentation.boundary_train import main as train_main
from arm_training.segmentation.outline_train import belongs


def test_datagen_and_training_write_weights_the_segmentation_loads(tmp_path):
    arrays = make_shard(seed=3, split="train", views=1)
    assert arrays["rgb"].shape == (1, 240, 320, 3) and arrays["labels"].max() > 0
    for split in ("train", "test"):
        (tmp_path / "data" / split).mkdir(parents=True)
        np.savez_compressed(tmp_path / "data" / split / "shard_000003.npz", **arrays)
    out = tmp_path / "boundary.pt"
    args = ["--data", str(tmp_path / "data"), "--out", str(out), "--steps", "2", "--batch", "2", "--threads", "1"]
    assert train_main(args) == 0
    assert out.is_file() and out.with_suffix(".md").is_file() and out.with_suffix(".state").is_file()
    predictor = BoundaryPredictor(out)
    features = boundary_features(
        arrays["rgb"][0], arrays["depth"][0].astype(np.float32), arrays["normals"][0] / 127.0, arrays["height"][0]
    )
    probability = predictor.predict(features)
    assert probability.shape == (2, 240, 320) and np.all((probability >= 0) & (probability <= 1))
    assert train_main(args) == 0  # resumes from the saved state: already finished, scores and exports again
    timed = tmp_path / "timed.pt"
    args = ["--data", str(tmp_path / "data"), "--out", str(timed), "--steps", "0", "--minutes", "0.5",
            "--batch", "2", "--crop-height", "32", "--crop-width", "32", "--threads", "1",
            "--export-unfinished"]  # fmt: skip
    assert train_main(args) == 0
    state = torch.load(timed.with_suffix(".state"), weights_only=False)
    # the step count was fixed from a timed trial and saved for a resume; the run ended by it or by the
    # deadline (how many steps fit depends on this machine's load), and the weights were written
    assert state["steps"] >= 50 and 0 < state["step"] <= state["steps"] and timed.is_file()


def test_crops_are_windows_of_the_frames_mirrored_with_the_normal_turned():
    rng = np.random.default_rng(0)
    labels = np.zeros((24, 40), np.uint16)
    labels[4:14, 5:20], labels[8:20, 18:33] = 1, 2
    normals = rng.integers(-127, 128, (24, 40, 3)).astype(np.int8)
    height = rng.uniform(0.0, 0.2, (24, 40)).astype(np.float16)
    rgb = rng.integers(0, 256, (24, 40, 3)).astype(np.uint8)
    features, targets = frame_arrays(rgb, np.full((24, 40), 0.8, np.float16), normals, height, labels)
    assert targets[0].any() and (targets[1] == (labels > 0)).all() and targets[2].sum() > targets[1].sum()
    generator = torch.Generator().manual_seed(1)
    x, y = crop_batch(torch.from_numpy(features[None]), torch.from_numpy(targets[None]), generator, 16, (8, 12))
    assert x.shape == (16, FEATURE_CHANNELS, 8, 12) and y.shape == (16, 3, 8, 12)
    frame = features.astype(np.float32)
    turn = np.where(np.arange(FEATURE_CHANNELS) == NORMAL_X_CHANNEL, -1, 1)[:, None, None]
    mirrored = 0
    for crop in x.numpy():
        matches = []
        for y0 in range(24 - 8 + 1):
            for x0 in range(40 - 12 + 1):
                window = frame[:, y0 : y0 + 8, x0 : x0 + 12]
                for candidate, was_flipped in ((window, False), (window[:, :, ::-1] * turn, True)):
                    if np.allclose(crop[3:], candidate[3:], atol=1e-3):  # colour is jittered, geometry is not
                        matches.append(was_flipped)
        assert matches, "a crop that is no window of the frame"
        mirrored += matches[0]
    assert 0 < mirrored < 16


def test_belongs_is_the_true_object_the_candidate_mostly_covers():
    truth = np.zeros((30, 40), np.uint16)
    truth[5:20, 5:15], truth[5:20, 15:30] = 1, 2
    labels = np.zeros_like(truth)
    labels[4:21, 4:17] = 1  # object 1 plus a sliver of object 2 and a background rim
    band = outline_band(labels, 2)
    result = belongs(labels, truth, band)
    on = truth[band.rows, band.cols]
    assert np.all(result == (on == 1))
    assert not np.any(belongs(labels, np.zeros_like(truth), band))


def test_seg_outline_train_makes_shards_trains_and_resumes(tmp_path):
    from arm_training.segmentation.outline_train import main

    out = tmp_path / "outline.npz"
    args = ["--data", str(tmp_path / "data"), "--train-shards", "1", "--test-shards", "1", "--views", "1"]
    args += ["--steps", "5", "--hidden", "4", "--batch", "64", "--out", str(out)]
    assert main(args) == 0
    classifier = OutlineClassifier(out)
    assert classifier.layers[0][0].shape == (len(FEATURE_NAMES), 4)
    assert (tmp_path / "outline.md").read_text().startswith("# Outline classifier")
    shard = tmp_path / "data" / "train" / "shard_000000.npz"
    stamp = shard.stat().st_mtime_ns
    assert main(args) == 0
    assert shard.stat().st_mtime_ns == stamp
