"""Pixels without depth on the objects' outlines and in their notches (fill_enclosed_missing), and
beside them (trim_grown)."""

import numpy as np
import pytest
from scipy import ndimage

from arm_segmentation.segmentation import SegmentationParams, fill_enclosed_missing, fill_holes, trim_grown
from arm_segmentation.table_plane import SupportLevel


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


# a camera 1 m above the table looking straight down: depth 1 m is the table (world z = 0)
K = np.array([[500.0, 0.0, 40.0], [0.0, 500.0, 30.0], [0.0, 0.0, 1.0]])
T_WORLD_CAMERA = np.array([[1.0, 0, 0, 0], [0, -1.0, 0, 0], [0, 0, -1.0, 1.0], [0, 0, 0, 1.0]])
TABLE = SupportLevel(0.0, 1.0, np.zeros((0, 3)), np.zeros((0, 2)))


def _red_box_on_grey_table_with_a_grown_band(band_rgb, band_depth_m: float):
    """A red 20x20 box 10 cm high on a grey table, a 12 px band left of it coloured band_rgb at
    band_depth_m (0: no return), and the labels after a growth that gave the band to the box."""
    rgb = np.full((60, 80, 3), 120, dtype=np.uint8)
    rgb[20:40, 40:60] = (200, 30, 30)
    rgb[20:40, 28:40] = band_rgb
    depth = np.ones((60, 80), dtype=np.float32)
    depth[20:40, 40:60] = 0.9
    depth[20:40, 28:40] = band_depth_m
    labels = np.zeros((60, 80), dtype=np.uint16)
    labels[20:40, 40:60] = 1
    grown = labels.copy()
    grown[20:40, 28:40] = 1
    return labels, grown, depth, rgb


def _trim(labels, grown, depth, rgb):
    return trim_grown(labels, grown, depth, rgb, K, T_WORLD_CAMERA, [TABLE], SegmentationParams())


@pytest.mark.parametrize("band_depth_m", [0.0, 1.0])
def test_grown_band_that_looks_like_the_table_is_trimmed(band_depth_m):
    """A projector's shadow (no depth), or the table beside the base: the colour camera sees the table."""
    labels, grown, depth, rgb = _red_box_on_grey_table_with_a_grown_band((118, 122, 120), band_depth_m)
    assert np.array_equal(_trim(labels, grown, depth, rgb), labels)


@pytest.mark.parametrize("band_depth_m", [0.0, 1.0])
def test_grown_band_that_looks_like_the_object_stays(band_depth_m):
    """A dark or shiny side of the object without depth, or its base at the table's height (the
    chromaticity is smoothed, so the band's outer corners may blend with the table)."""
    labels, grown, depth, rgb = _red_box_on_grey_table_with_a_grown_band((190, 40, 35), band_depth_m)
    trimmed = _trim(labels, grown, depth, rgb)
    assert np.count_nonzero(trimmed[20:40, 28:40] == 1) >= 0.98 * 20 * 12
    assert np.array_equal(trimmed[labels > 0], grown[labels > 0])


def test_grown_band_with_depth_above_the_table_stays_whatever_its_colour():
    labels, grown, depth, rgb = _red_box_on_grey_table_with_a_grown_band((118, 122, 120), 0.95)
    assert np.array_equal(_trim(labels, grown, depth, rgb), grown)
