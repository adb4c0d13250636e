import numpy as np
import pytest

from arm_segmentation.metrics import boundary_map, segmentation_metrics


def two_squares():
    gt = np.zeros((60, 80), np.uint16)
    gt[10:30, 10:30] = 1
    gt[10:30, 40:70] = 2
    return gt


def test_perfect_prediction_with_other_ids_scores_one():
    gt = two_squares()
    pred = np.where(gt == 1, 7, np.where(gt == 2, 3, 0)).astype(np.uint16)
    m = segmentation_metrics(pred, gt)
    for key in ("overlap_precision", "overlap_recall", "overlap_f", "boundary_f", "f_at_75"):
        assert m[key] == pytest.approx(1.0)
    assert (m["n_pred"], m["n_gt"]) == (2, 2)


def test_merged_objects_lose_recall_not_precision():
    gt = two_squares()
    pred = (gt > 0).astype(np.uint16)
    m = segmentation_metrics(pred, gt)
    assert m["overlap_precision"] == pytest.approx(600 / 1000)
    assert m["overlap_recall"] == pytest.approx(600 / 1000)
    assert m["f_at_75"] == 0.0  # the larger square's F is exactly 0.75, not above


def test_split_object_is_matched_once():
    gt = two_squares()
    pred = gt.copy()
    pred[10:30, 55:70] = 5  # right square split in two halves
    m = segmentation_metrics(pred, gt)
    assert m["overlap_precision"] == pytest.approx(1.0 - 300 / 1000)
    assert m["overlap_recall"] == pytest.approx(1.0 - 300 / 1000)
    assert m["f_at_75"] == pytest.approx(0.5)  # the half has F = 2/3


def test_boundary_tolerance_accepts_small_shifts():
    gt = np.zeros((480, 640), np.uint16)
    gt[100:200, 100:300] = 1
    shifted = np.roll(gt, 2, axis=1)
    far = np.roll(gt, (12, 12), axis=(0, 1))
    assert segmentation_metrics(shifted, gt)["boundary_f"] == pytest.approx(1.0)
    assert segmentation_metrics(far, gt)["boundary_f"] < 0.6


def test_empty_cases():
    empty = np.zeros((20, 20), np.uint16)
    one = empty.copy()
    one[5:10, 5:10] = 1
    assert segmentation_metrics(empty, empty)["overlap_f"] == 1.0
    assert segmentation_metrics(empty, one)["overlap_f"] == 0.0
    assert segmentation_metrics(one, empty)["overlap_f"] == 0.0
    with pytest.raises(ValueError):
        segmentation_metrics(one, np.zeros((5, 5), np.uint16))


def test_boundary_map_of_square():
    mask = np.zeros((10, 10), bool)
    mask[2:6, 2:6] = True
    b = boundary_map(mask)
    # one-pixel boundary, offset half a pixel towards the origin as in the DAVIS/UOIS code
    assert b[1, 1] and b[5, 5] and not b[3, 3] and not b[2, 2]
