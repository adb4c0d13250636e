"""The learned outline cue: targets, features, the network, its loading, its use by the clustering,
and one real data-generation and training step end to end."""

import numpy as np
import pytest
import torch
from seg_fixtures import Box, look_at, render

import arm_segmentation.segmentation as segmentation
from arm_segmentation import boundary_net
from arm_segmentation.boundary_net import (
    FEATURE_CHANNELS,
    BoundaryParams,
    boundary_features,
    boundary_targets,
    build_network,
    shared_predictor,
)
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
    assert shared_predictor(BoundaryParams(fill_objects=False)) is None
    with pytest.raises(FileNotFoundError):
        shared_predictor(BoundaryParams(checkpoint=str(tmp_path / "none.pt")))
    (tmp_path / "garbage.pt").write_text("not weights")
    with pytest.raises(ValueError, match="not boundary network weights"):
        shared_predictor(BoundaryParams(checkpoint=str(tmp_path / "garbage.pt")))
    monkeypatch.setattr(boundary_net, "DEFAULT_CHECKPOINT", tmp_path / "absent.pt")
    monkeypatch.setattr(boundary_net, "_PREDICTORS", {})
    assert shared_predictor(BoundaryParams()) is None  # shipped weights absent: geometric cues only


def test_shipped_weights_load_and_separate_differently_coloured_boxes():
    camera = look_at((-0.45, 0.1, 0.6), (0.05, 0.0, 0.0))
    boxes = [Box((0.0, -0.05, 0.04), (0.04, 0.05, 0.04), 0.0, (200, 40, 40)),
             Box((0.0, 0.05, 0.04), (0.04, 0.05, 0.04), 0.0, (40, 170, 60))]  # fmt: skip
    rgb, depth, truth, K = render(boxes, camera)
    params = segmentation.SegmentationParams()
    assert shared_predictor(params.boundary) is not None
    labels = segmentation.segment(rgb, depth, K, camera, params)
    assert segmentation_metrics(labels, truth)["overlap_f"] > 0.9


def test_object_channel_gives_an_object_the_base_geometry_left_out(monkeypatch):
    camera = look_at((-0.5, 0.0, 0.45), (0.0, 0.0, 0.0))
    # a box with a dark, matte foot that loses its depth: the geometry leaves it out, the object
    # channel gives it back (a foot that looked like the table beside it would pass for a shadow)
    boxes = [Box((0.0, 0.0, 0.04), (0.04, 0.05, 0.04), rgb=(40, 60, 200))]
    rgb, depth, truth, K = render(boxes, camera)
    rows = np.nonzero(np.any(truth == 1, axis=1))[0]
    foot = (truth == 1) & (np.arange(truth.shape[0])[:, None] > rows.max() - 0.2 * (rows.max() - rows.min()))
    depth = np.where(foot, np.float32(0.0), depth)
    rgb = np.where(foot[..., None], np.array([15, 20, 70], np.uint8), rgb)
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
