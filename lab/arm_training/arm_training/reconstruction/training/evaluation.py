"""Held-out evaluation: per-sample voxel IoU, Chamfer distance, stability and connectedness."""

from __future__ import annotations

import numpy as np
import torch
from scipy import ndimage

from arm_reconstruction.network import select_input_channels
from arm_training.reconstruction.dataset import VoxelDataset
from arm_training.reconstruction.losses import stability_value_and_gradient


def voxel_metrics(
    probabilities: np.ndarray, occupancy: np.ndarray, voxel_size_m: np.ndarray, others: np.ndarray | None = None
) -> dict[str, np.ndarray]:
    """Per-sample IoU at 0.5, symmetric voxel Chamfer distance (metres: mean distance from each
    predicted voxel centre to the nearest true one plus the converse), whether the thresholded
    prediction is statically stable (stability prior P(E) > 0.5 on 0/1 occupancy, table and the
    other objects' true occupancy as support) and whether it is one 26-connected component."""
    predicted = probabilities >= 0.5
    truth = occupancy >= 0.5
    intersection = (predicted & truth).sum(axis=(1, 2, 3))
    union = (predicted | truth).sum(axis=(1, 2, 3))
    iou = np.where(union > 0, intersection / np.maximum(union, 1), 1.0)
    chamfer = np.zeros(len(predicted))
    components = np.zeros(len(predicted), dtype=np.int64)
    structure = np.ones((3, 3, 3), bool)
    for n in range(len(predicted)):
        if predicted[n].any() and truth[n].any():
            to_truth = ndimage.distance_transform_edt(~truth[n])[predicted[n]].mean()
            to_predicted = ndimage.distance_transform_edt(~predicted[n])[truth[n]].mean()
            chamfer[n] = (to_truth + to_predicted) * voxel_size_m[n]
        else:
            chamfer[n] = np.nan
        components[n] = ndimage.label(predicted[n], structure)[1]
    result = {"iou": iou, "chamfer_m": chamfer, "single_component": components == 1}
    if others is not None:
        hard_logits = torch.from_numpy(np.where(predicted, 30.0, -30.0).astype(np.float32))
        log_stable, _ = stability_value_and_gradient(hard_logits, torch.from_numpy(others), with_gradient=False)
        result["stable"] = (log_stable.numpy() > np.log(0.5)) & predicted.any(axis=(1, 2, 3))
    return result


def evaluate(model, dataset: VoxelDataset, device, max_samples: int = 512, batch_size: int = 32) -> dict:
    """Mean held-out metrics over the first ``max_samples`` samples (all, by visibility bins)."""
    model.eval()
    count = min(len(dataset), max_samples) if max_samples else len(dataset)
    parts: dict[str, list] = {}
    with torch.no_grad():
        for start in range(0, count, batch_size):
            index = np.arange(start, min(start + batch_size, count))
            batch = dataset.batch(index, device)
            logits = model(select_input_channels(batch["grids"], model.in_channels))
            metrics = voxel_metrics(
                torch.sigmoid(logits).float().cpu().numpy(),
                batch["occupancy"].cpu().numpy(),
                dataset.info["voxel_size_m"][index],
                batch["others"].cpu().numpy(),
            )
            metrics["visible_fraction"] = dataset.info["visible_fraction"][index]
            for key, value in metrics.items():
                parts.setdefault(key, []).append(value)
    model.train()
    values = {key: np.concatenate(value) for key, value in parts.items()}
    occluded = values.pop("visible_fraction") < 0.7
    summary = {"samples": int(count), "occluded_samples": int(occluded.sum())}
    for key, value in values.items():
        summary[key] = _finite_mean(value)
        summary[f"{key}_occluded"] = _finite_mean(value[occluded])
    return summary


def _finite_mean(values: np.ndarray) -> float | None:
    """Mean over the defined entries (Chamfer is undefined for an empty prediction), None if none."""
    values = np.asarray(values, dtype=np.float64)
    defined = values[np.isfinite(values)]
    return float(defined.mean()) if len(defined) else None
