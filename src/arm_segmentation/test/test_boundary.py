import numpy as np
import pytest
from scipy import ndimage

from arm_segmentation.boundary import BorderParams, grow_into_objectness, nearest_pixel, refine_borders


def _scene():
    rgb = np.full((60, 80, 3), 120, dtype=np.uint8)
    rgb[20:40, 10:30] = (200, 30, 30)
    rgb[20:40, 50:70] = (30, 160, 40)
    truth = np.zeros((60, 80), dtype=np.uint16)
    truth[20:40, 10:30] = 1
    truth[20:40, 50:70] = 2
    return rgb, truth


@pytest.mark.parametrize("offset", [-2, 2])
def test_outline_off_by_two_pixels_is_moved_to_the_colour_edge(offset):
    rgb, truth = _scene()
    labels = np.zeros_like(truth)
    labels[20 - offset : 40 + offset, 10 - offset : 30 + offset] = 1
    labels[20 - offset : 40 + offset, 50 - offset : 70 + offset] = 2
    refined = refine_borders(labels, rgb, BorderParams(band_px=2))
    assert refined.dtype == labels.dtype
    assert np.count_nonzero(refined != truth) <= 20  # the corners round off (disc-shaped band)
    assert np.count_nonzero(labels != truth) > 100


def test_no_instances_or_zero_band_leave_labels_unchanged():
    rgb, truth = _scene()
    empty = np.zeros_like(truth)
    assert np.array_equal(refine_borders(empty, rgb), empty)
    assert np.array_equal(refine_borders(truth, rgb, BorderParams(band_px=0)), truth)


def test_nearest_pixel_is_a_nearest_mask_pixel():
    rng = np.random.default_rng(3)
    mask = rng.random((50, 70)) < 0.02
    ys, xs = np.indices(mask.shape)
    rows, cols = nearest_pixel(mask, (ys, xs))
    assert np.all(mask[rows, cols])
    exact, _ = ndimage.distance_transform_edt(~mask, return_indices=True)
    found = np.hypot(rows - ys, cols - xs)
    near = exact <= 3
    assert np.allclose(found[near], exact[near])
    assert np.all(found <= exact + 1.0)


def test_grow_into_objectness_gives_near_object_pixels_to_the_nearest_instance():
    labels = np.zeros((60, 80), np.uint16)
    labels[10:30, 10:30] = 1
    labels[10:30, 50:70] = 2
    objectness = np.zeros((60, 80), np.float32)
    objectness[30:36, 10:30] = 0.95  # a flat base under instance 1, left out by geometry
    objectness[30:36, 50:70] = 0.5  # below the threshold: stays background
    objectness[50:60, 0:80] = 0.99  # object-like but beyond reach of every instance
    grown = grow_into_objectness(labels, objectness, threshold=0.9, reach_px=10)
    assert np.all(grown[30:36, 10:30] == 1)
    assert not np.any(grown[30:36, 50:70]) and not np.any(grown[50:60])
    assert np.array_equal(grown[labels > 0], labels[labels > 0])  # labelled pixels are never changed


def test_grow_into_objectness_without_instances_or_reach_is_a_no_op():
    objectness = np.ones((20, 20), np.float32)
    empty = np.zeros((20, 20), np.uint16)
    assert not np.any(grow_into_objectness(empty, objectness, 0.5, 10))
    labels = empty.copy()
    labels[5:10, 5:10] = 1
    assert np.array_equal(grow_into_objectness(labels, objectness, 0.5, 0), labels)
