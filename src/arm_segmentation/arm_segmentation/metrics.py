"""Unseen-object instance segmentation metrics as defined in the UOIS papers.

Overlap P/R/F (Dave et al. 2019, used by Xie et al. UOIS-Net): predicted and ground-truth objects
are matched by the Hungarian algorithm on their pairwise F-measure; precision is the matched true
positive pixels over all predicted object pixels, recall the same over all ground-truth object
pixels. Boundary P/R/F uses the same matching on one-pixel boundaries, a predicted boundary pixel
counting as correct within a disk of ceil(0.003 * image diagonal) pixels of the ground-truth
boundary (and vice versa). F@75% is the fraction of ground-truth objects whose matched prediction
has an overlap F-measure above 0.75. Label 0 is background / table in both images.
"""

import cv2
import numpy as np
from scipy.optimize import linear_sum_assignment

BOUNDARY_TOLERANCE = 0.003
DETECTION_THRESHOLD = 0.75


def boundary_map(mask: np.ndarray) -> np.ndarray:
    """One-pixel boundary of a binary mask (pixels differing from their E, S or SE neighbour)."""
    m = mask.astype(bool)
    east = np.zeros_like(m)
    south = np.zeros_like(m)
    south_east = np.zeros_like(m)
    east[:, :-1] = m[:, 1:]
    south[:-1, :] = m[1:, :]
    south_east[:-1, :-1] = m[1:, 1:]
    b = (m ^ east) | (m ^ south) | (m ^ south_east)
    b[-1, :] = m[-1, :] ^ east[-1, :]
    b[:, -1] = m[:, -1] ^ south[:, -1]
    b[-1, -1] = False
    return b


def _disk(radius: int) -> np.ndarray:
    y, x = np.mgrid[-radius : radius + 1, -radius : radius + 1]
    return (x * x + y * y <= radius * radius).astype(np.uint8)


def _f(p, r):
    return 0.0 if p + r <= 0 else float(2.0 * p * r / (p + r))


def segmentation_metrics(prediction: np.ndarray, ground_truth: np.ndarray) -> dict:
    """UOIS metrics of one label image against its ground truth (both HxW integer, 0 = no object).

    Returns overlap_{precision,recall,f}, boundary_{precision,recall,f}, f_at_75 (fraction of
    ground-truth objects detected with overlap F > 0.75), n_pred, n_gt, instances_per_object
    (n_pred / n_gt, NaN without objects) and background_fp_fraction (share of the predicted object
    pixels that are background in the ground truth).
    """
    prediction = np.asarray(prediction)
    ground_truth = np.asarray(ground_truth)
    if prediction.shape != ground_truth.shape:
        raise ValueError(f"shape mismatch {prediction.shape} vs {ground_truth.shape}")
    gt_ids, gt_index = np.unique(ground_truth, return_inverse=True)
    pred_ids, pred_index = np.unique(prediction, return_inverse=True)
    gt_index = gt_index.reshape(ground_truth.shape)
    pred_index = pred_index.reshape(prediction.shape)
    n_gt = int(np.count_nonzero(gt_ids))
    n_pred = int(np.count_nonzero(pred_ids))
    predicted = prediction != 0
    result = {
        "n_pred": n_pred,
        "n_gt": n_gt,
        "instances_per_object": n_pred / n_gt if n_gt else float("nan"),
        "background_fp_fraction": float(np.mean(ground_truth[predicted] == 0)) if predicted.any() else 0.0,
    }
    if n_gt == 0 or n_pred == 0:
        perfect = float(n_gt == 0 and n_pred == 0)
        p = 1.0 if n_pred == 0 else 0.0
        r = 1.0 if n_gt == 0 else 0.0
        result.update(
            overlap_precision=p,
            overlap_recall=r,
            overlap_f=perfect,
            boundary_precision=p,
            boundary_recall=r,
            boundary_f=perfect,
            f_at_75=perfect,
        )
        return result
    gt_first = int(gt_ids[0] != 0)
    pred_first = int(pred_ids[0] != 0)
    n_g, n_p = len(gt_ids), len(pred_ids)
    table = np.bincount((gt_index * n_p + pred_index).ravel(), minlength=n_g * n_p).reshape(n_g, n_p)
    gt_offset = 1 - gt_first
    pred_offset = 1 - pred_first
    tp = table[gt_offset:, pred_offset:].astype(np.float64)
    gt_size = table.sum(axis=1)[gt_offset:].astype(np.float64)
    pred_size = table.sum(axis=0)[pred_offset:].astype(np.float64)
    precision_pair = tp / pred_size[None, :]
    recall_pair = tp / gt_size[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        f_pair = np.nan_to_num(2 * precision_pair * recall_pair / (precision_pair + recall_pair))
    rows, cols = linear_sum_assignment(-f_pair)
    overlap_p = tp[rows, cols].sum() / pred_size.sum()
    overlap_r = tp[rows, cols].sum() / gt_size.sum()
    detected = int(np.count_nonzero(f_pair[rows, cols] > DETECTION_THRESHOLD))

    radius = int(np.ceil(BOUNDARY_TOLERANCE * np.hypot(*prediction.shape)))
    disk = _disk(radius)
    gt_bounds = [boundary_map(gt_index == i + gt_offset) for i in range(n_gt)]
    pred_bounds = [boundary_map(pred_index == j + pred_offset) for j in range(n_pred)]
    precision_tp = recall_tp = 0
    for i, j in zip(rows, cols, strict=True):
        gt_dilated = cv2.dilate(gt_bounds[i].astype(np.uint8), disk) > 0
        pred_dilated = cv2.dilate(pred_bounds[j].astype(np.uint8), disk) > 0
        precision_tp += np.count_nonzero(pred_bounds[j] & gt_dilated)
        recall_tp += np.count_nonzero(gt_bounds[i] & pred_dilated)
    boundary_p = precision_tp / max(sum(int(b.sum()) for b in pred_bounds), 1)
    boundary_r = recall_tp / max(sum(int(b.sum()) for b in gt_bounds), 1)
    result.update(
        overlap_precision=float(overlap_p),
        overlap_recall=float(overlap_r),
        overlap_f=_f(overlap_p, overlap_r),
        boundary_precision=float(boundary_p),
        boundary_recall=float(boundary_r),
        boundary_f=_f(boundary_p, boundary_r),
        f_at_75=detected / n_gt,
    )
    return result
