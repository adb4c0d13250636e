import numpy as np
import pytest
from scipy import ndimage

from arm_segmentation.boundary import BorderParams, outline_band, refine_borders
from arm_segmentation.outline_model import (
    DEFAULT_CHECKPOINT,
    FEATURE_NAMES,
    OutlineParams,
    outline_features,
    outline_image,
    refine_outline,
    shared_outline_classifier,
)


def _disc_scene(radius_px=18):
    """A red disc (a cylinder 5 cm nearer than the table) on a wood-like striped table, 100x120 px."""
    rng = np.random.default_rng(1)
    yy, xx = np.mgrid[:100, :120]
    table = 110 + 25 * np.sin(xx / 3.0)[..., None] + rng.normal(0, 4, (100, 120, 1))
    rgb = np.clip(np.broadcast_to(table, (100, 120, 3)) * [1.0, 0.8, 0.6], 0, 255)
    disc = (yy - 50) ** 2 + (xx - 60) ** 2 <= radius_px**2
    rgb[disc] = (190, 35, 30) + rng.normal(0, 4, (disc.sum(), 3))
    depth = np.where(disc, 0.75, 0.80).astype(np.float32)
    objectness = ndimage.gaussian_filter(disc.astype(np.float32), 2.0)
    return rgb.astype(np.uint8), depth, objectness, disc


def test_the_band_follows_the_outline_not_the_image_border():
    labels = np.zeros((40, 50), np.uint16)
    labels[:15, :20] = 1  # touches the top and left borders
    band = outline_band(labels, 2)
    near_outline = (np.abs(band.rows - 14.5) <= 3) | (np.abs(band.cols - 19.5) <= 3)
    assert np.all(near_outline) and np.all(band.candidate == 1)
    assert outline_band(np.zeros_like(labels), 2) is None


def test_the_colour_rule_leaves_background_far_from_an_outline_alone():
    rgb = np.random.default_rng(0).integers(0, 255, (60, 80, 3), dtype=np.uint8)  # clutter everywhere
    rgb[20:40, 20:50] = (200, 30, 30)
    labels = np.zeros((60, 80), np.uint16)
    labels[20:40, 20:50] = 1
    refined = refine_borders(labels, rgb, BorderParams(band_px=2))
    far = ndimage.distance_transform_edt(labels == 0) > 3
    assert not np.any(refined[far])


def test_features_have_one_finite_column_per_name():
    rgb, depth, objectness, disc = _disc_scene()
    labels = disc.astype(np.uint16)
    band = outline_band(labels, 2)
    features = outline_features(labels, outline_image(rgb, depth, objectness, blur_px=3), band)
    assert features.shape == (len(band.rows), len(FEATURE_NAMES)) and np.all(np.isfinite(features))
    signed = features[:, FEATURE_NAMES.index("signed_distance_px")]
    covered = labels[band.rows, band.cols] > 0
    assert np.all(signed[covered] > 0) and np.all(signed[~covered] < 0)


@pytest.mark.parametrize("grow_px", [-2, 2])
def test_the_shipped_classifier_moves_an_outline_two_pixels_off_back_to_the_object(grow_px):
    classifier = shared_outline_classifier(OutlineParams())
    assert classifier is not None, f"shipped weights missing: {DEFAULT_CHECKPOINT}"
    rgb, depth, objectness, disc = _disc_scene()
    labels = _disc_scene(18 + grow_px)[3].astype(np.uint16)
    refined = refine_outline(labels, rgb, depth, objectness, classifier, OutlineParams())
    assert refined.dtype == labels.dtype
    wrong_before = np.count_nonzero((labels > 0) != disc)
    assert np.count_nonzero((refined > 0) != disc) <= 0.25 * wrong_before
