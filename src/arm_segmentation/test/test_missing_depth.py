"""Pixels without depth on the objects' outlines and in their notches (fill_enclosed_missing), and
beside them (trim_grown_missing)."""

import numpy as np
from scipy import ndimage

from arm_segmentation.segmentation import SegmentationParams, fill_enclosed_missing, fill_holes, trim_grown_missing


def _notched_square():
    """A 30x30 instance with a 4 px wide notch cut into its right side, and the depth image."""
    labels = np.zeros((60, 60), dtype=np.uint16)
    labels[15:45, 15:45] = 1
    labels[28:32, 35:45] = 0
    depth = np.ones((60, 60), dtype=np.float32)
    return labels, depth


def test_notch_without_depth_is_filled_by_the_closing():
    labels, depth = _notched_square()
    depth[28:32, 35:45] = 0.0
    assert np.array_equal(fill_enclosed_missing(labels, depth), labels)  # not enclosed
    filled = fill_enclosed_missing(labels, depth, close_px=6)
    assert np.all(filled[28:32, 35:45] == 1)
    assert np.count_nonzero(filled) == 30 * 30


def test_notch_with_depth_and_the_background_stay_unlabelled():
    labels, depth = _notched_square()
    depth[:, 50:] = 0.0  # no depth beyond the object, out of the closing's reach
    filled = fill_enclosed_missing(labels, depth, close_px=6)
    assert np.array_equal(filled, labels)


def test_enclosed_hole_goes_to_the_surrounding_instance():
    labels = np.zeros((40, 40), dtype=np.uint16)
    labels[5:35, 5:20] = 1
    labels[5:35, 20:35] = 2
    labels[15:20, 8:14] = 0
    depth = np.ones((40, 40), dtype=np.float32)
    depth[15:20, 8:14] = 0.0
    filled = fill_enclosed_missing(labels, depth)
    assert np.all(filled[15:20, 8:14] == 1)


def test_fill_holes_matches_scipy_binary_fill_holes():
    rng = np.random.default_rng(4)
    for _ in range(100):
        mask = rng.random((int(rng.integers(1, 60)), int(rng.integers(1, 80)))) < rng.uniform(0.2, 0.9)
        assert np.array_equal(fill_holes(mask), ndimage.binary_fill_holes(mask))


def _red_box_on_grey_table_with_a_band_without_depth(band_rgb):
    """A red 20x20 instance on a grey table, a 12 px band without depth left of it coloured band_rgb,
    and the labels after a growth that gave the band to the box."""
    rgb = np.full((60, 80, 3), 120, dtype=np.uint8)
    rgb[20:40, 40:60] = (200, 30, 30)
    rgb[20:40, 28:40] = band_rgb
    depth = np.ones((60, 80), dtype=np.float32)
    depth[20:40, 28:40] = 0.0
    labels = np.zeros((60, 80), dtype=np.uint16)
    labels[20:40, 40:60] = 1
    grown = labels.copy()
    grown[20:40, 28:40] = 1
    return labels, grown, depth, rgb


def test_grown_band_without_depth_that_looks_like_the_table_is_trimmed():
    """A projector's shadow: the colour camera sees the table there."""
    labels, grown, depth, rgb = _red_box_on_grey_table_with_a_band_without_depth((118, 122, 120))
    trimmed = trim_grown_missing(labels, grown, depth, rgb, SegmentationParams())
    assert np.array_equal(trimmed, labels)


def test_grown_band_without_depth_that_looks_like_the_object_stays():
    """A dark or shiny side of the object that returned no depth (the chromaticity is smoothed, so
    the band's outer corners may blend with the table)."""
    labels, grown, depth, rgb = _red_box_on_grey_table_with_a_band_without_depth((190, 40, 35))
    trimmed = trim_grown_missing(labels, grown, depth, rgb, SegmentationParams())
    band = grown[20:40, 28:40]
    assert np.count_nonzero(trimmed[20:40, 28:40] == band) >= 0.98 * band.size
    assert np.array_equal(trimmed[labels > 0], grown[labels > 0])
