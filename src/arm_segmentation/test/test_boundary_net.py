"""The learned outline cue: targets, features, the network, its loading, its use by the clustering,
and one real data-generation and training step end to end."""

import numpy as np
import pytest
import torch
from seg_fixtures import Box, look_at, render

import arm_segmentation.segmentation as segmentation
from arm_segmentation import boundary_net
from arm_segmentation.boundary_data import make_shard
from arm_segmentation.boundary_net import (
    FEATURE_CHANNELS,
    BoundaryParams,
    BoundaryPredictor,
    boundary_features,
    boundary_targets,
    build_network,
    shared_predictor,
)
from arm_segmentation.boundary_train import NORMAL_X_CHANNEL, crop_batch, frame_arrays
from arm_segmentation.boundary_train import main as train_main
from arm_segmentation.metrics import segmentation_metrics


def test_targets_mark_where_objects_meet_and_nothing_else():
    labels = np.zeros((20, 30), dtype=np.uint16)
    labels[5:15, 5:15] = 1
    labels[5:15, 15:25] = 2
    outline = boundary_targets(labels, radius_px=1)
    assert outline[10, 14] and outline[10, 15]  # object / object, both sides
    assert not outline[10, 4] and not outline[10, 5]  # background / object: geometry's job
    assert not outline[10, 10] and not outline[10, 20] and not outline[0, 0]


def test_features_have_fixed_channels_and_no_nan():
    h, w = 12, 16
    rgb = np.full((h, w, 3), 128, np.uint8)
    depth = np.ones((h, w), np.float32)
    depth[0, 0] = 0.0
    height = np.full((h, w), np.nan, np.float32)
    features = boundary_features(rgb, depth, np.zeros((h, w, 3), np.float32), height)
    assert features.shape == (FEATURE_CHANNELS, h, w) and features.dtype == np.float32
    assert np.all(np.isfinite(features))


def test_network_keeps_the_image_size_for_any_frame_size():
    model = build_network(4).eval()
    with torch.inference_mode():
        assert model(torch.zeros(1, FEATURE_CHANNELS, 50, 70)).shape == (1, 2, 50, 70)


def test_used_for_the_fill_by_default_and_missing_weights(tmp_path, monkeypatch):
    assert shared_predictor(BoundaryParams()) is not None  # the shipped weights, for the object fill
    assert shared_predictor(BoundaryParams(enabled=False, fill_objects=False)) is None
    with pytest.raises(FileNotFoundError):
        shared_predictor(BoundaryParams(enabled=True, checkpoint=str(tmp_path / "none.pt")))
    (tmp_path / "garbage.pt").write_text("not weights")
    with pytest.raises(ValueError, match="not boundary network weights"):
        shared_predictor(BoundaryParams(enabled=True, checkpoint=str(tmp_path / "garbage.pt")))
    monkeypatch.setattr(boundary_net, "DEFAULT_CHECKPOINT", tmp_path / "absent.pt")
    monkeypatch.setattr(boundary_net, "_PREDICTORS", {})
    assert shared_predictor(BoundaryParams(enabled=True)) is None  # shipped weights absent: geometric cues only


def test_outline_cue_separates_flush_boxes_of_one_colour(monkeypatch):
    camera = look_at((-0.5, 0.0, 0.55), (0.0, 0.0, 0.0))
    boxes = [Box((0.0, -0.04, 0.05), (0.04, 0.04, 0.05)), Box((0.0, 0.04, 0.05), (0.04, 0.04, 0.05))]
    rgb, depth, truth, K = render(boxes, camera)
    off = segmentation.SegmentationParams(boundary=BoundaryParams(enabled=False))
    merged = segmentation.segment(rgb, depth, K, camera, off)
    assert segmentation_metrics(merged, truth)["n_pred"] == 1  # one continuous surface, one colour

    stride = off.working_stride
    outline = boundary_targets(truth[::stride, ::stride]).astype(np.float32)
    maps = np.stack([outline, np.zeros_like(outline)])
    monkeypatch.setattr(segmentation, "learned_maps", lambda *args: maps)
    with_network = segmentation.SegmentationParams(boundary=BoundaryParams(enabled=True))
    labels = segmentation.segment(rgb, depth, K, camera, with_network)
    metrics = segmentation_metrics(labels, truth)
    assert metrics["n_pred"] == 2 and metrics["overlap_f"] > 0.9


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


def test_shipped_weights_load_and_separate_differently_coloured_boxes():
    camera = look_at((-0.45, 0.1, 0.6), (0.05, 0.0, 0.0))
    boxes = [Box((0.0, -0.05, 0.04), (0.04, 0.05, 0.04), 0.0, (200, 40, 40)),
             Box((0.0, 0.05, 0.04), (0.04, 0.05, 0.04), 0.0, (40, 170, 60))]  # fmt: skip
    rgb, depth, truth, K = render(boxes, camera)
    params = segmentation.SegmentationParams(boundary=BoundaryParams(enabled=True))
    assert shared_predictor(params.boundary) is not None
    labels = segmentation.segment(rgb, depth, K, camera, params)
    assert segmentation_metrics(labels, truth)["overlap_f"] > 0.9


def test_object_channel_gives_an_object_the_base_geometry_left_out(monkeypatch):
    camera = look_at((-0.5, 0.0, 0.45), (0.0, 0.0, 0.0))
    # a box with a table-coloured foot 1.5 cm high that loses its depth (a dark, matte base)
    boxes = [Box((0.0, 0.0, 0.04), (0.04, 0.05, 0.04), rgb=(40, 60, 200))]
    rgb, depth, truth, K = render(boxes, camera)
    rows = np.nonzero(np.any(truth == 1, axis=1))[0]
    foot = (truth == 1) & (np.arange(truth.shape[0])[:, None] > rows.max() - 0.2 * (rows.max() - rows.min()))
    depth = np.where(foot, np.float32(0.0), depth)
    rgb = np.where(foot[..., None], np.array([150, 130, 110], np.uint8), rgb)
    off = segmentation.SegmentationParams(boundary=BoundaryParams(fill_objects=False))
    without = segmentation.segment(rgb, depth, K, camera, off)
    assert np.mean(without[foot] > 0) < 0.5  # geometry and colour leave most of the foot out

    stride = off.working_stride
    objectness = (truth[::stride, ::stride] > 0).astype(np.float32)
    maps = np.stack([np.zeros_like(objectness), objectness])
    monkeypatch.setattr(segmentation, "learned_maps", lambda *args: maps)
    filled = segmentation.segment(rgb, depth, K, camera, segmentation.SegmentationParams())
    assert np.mean(filled[foot] > 0) > 0.9 and np.all(filled[foot & (filled > 0)] == filled[truth == 1].max())
    assert segmentation_metrics(filled, truth)["overlap_f"] > segmentation_metrics(without, truth)["overlap_f"]
    assert np.mean(filled[truth == 0] > 0) < 0.01  # the table around it stays table
