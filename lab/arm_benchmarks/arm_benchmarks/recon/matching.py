"""Predicted instance masks matched to the true objects."""

from __future__ import annotations

import numpy as np

from arm_benchmarks.recon.config import MIN_MATCH_IOU


def match_instances(predicted, truth, truth_ids, min_iou: float = MIN_MATCH_IOU) -> dict[int, int]:
    """True id -> predicted id whose mask overlaps it with IoU > min_iou (one-to-one for min_iou >= 0.5)."""
    p = np.asarray(predicted).ravel().astype(np.int64)
    t = np.asarray(truth).ravel().astype(np.int64)
    n_p, n_t = int(p.max()) + 1, int(t.max()) + 1
    joint = np.bincount(t * n_p + p, minlength=n_t * n_p).reshape(n_t, n_p).astype(np.float64)
    union = joint.sum(1, keepdims=True) + joint.sum(0, keepdims=True) - joint
    iou = np.divide(joint, union, out=np.zeros_like(joint), where=union > 0)
    iou[:, 0] = 0.0
    match = {}
    for truth_id in truth_ids:
        if truth_id < n_t and iou[truth_id].max() > min_iou:
            match[int(truth_id)] = int(np.argmax(iou[truth_id]))
    return match
