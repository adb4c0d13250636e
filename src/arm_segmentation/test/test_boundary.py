import numpy as np
import pytest
from scipy import ndimage

from arm_segmentation.boundary import BorderParams, nearest_pixel, refine_borders


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
    rows, cols = nearest_pixel(mask)
    assert np.all(mask[rows, cols])
    exact, _ = ndimage.distance_transform_edt(~mask, return_indices=True)
    found = np.hypot(rows - np.arange(50)[:, None], cols - np.arange(70)[None, :])
    near = exact <= 3
    assert np.allclose(found[near], exact[near])
    assert np.all(found <= exact + 1.0)
