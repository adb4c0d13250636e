"""Each object's depth averaged over its own pixels (normalized box filter): noise smoothed and holes
filled without mixing objects or the background."""

import numpy as np
from scipy import ndimage


def _dense_labels(labels: np.ndarray, object_ids) -> np.ndarray:
    """labels renumbered 1..len(object_ids) in object_ids' order (0 elsewhere), for find_objects."""
    dense = np.zeros(labels.shape, dtype=np.int32)
    for n, object_id in enumerate(object_ids, start=1):
        dense[labels == object_id] = n
    return dense


def object_depth_average(
    depth_m: np.ndarray, labels: np.ndarray, object_ids, window_px: int, erosion_px: int = 0, fill_holes: bool = False
) -> np.ndarray:
    """HxW float32: at each pixel of an object in object_ids (its mask eroded by erosion_px), the mean
    depth (metres) of that object's pixels with a return in the window_px box around it; without
    fill_holes only pixels that have a return themselves get a value. 0 elsewhere."""
    depth_m, labels = np.asarray(depth_m, dtype=np.float32), np.asarray(labels)
    out = np.zeros_like(depth_m)
    margin = window_px + erosion_px + 1
    for object_id, box in zip(
        object_ids, ndimage.find_objects(_dense_labels(labels, object_ids), len(object_ids)), strict=True
    ):
        if box is None:
            continue
        crop = tuple(slice(max(0, s.start - margin), s.stop + margin) for s in box)
        mask = labels[crop] == object_id
        if erosion_px > 0:
            mask = ndimage.binary_erosion(mask, iterations=erosion_px)
        valid = mask & (depth_m[crop] > 0)
        if not valid.any():
            continue
        total = ndimage.uniform_filter(np.where(valid, depth_m[crop], 0.0), window_px, mode="constant")
        count = ndimage.uniform_filter(valid.astype(np.float32), window_px, mode="constant")
        target = (mask & (count > 1e-6)) if fill_holes else valid
        out[crop] = np.where(target, total / np.maximum(count, 1e-9), out[crop])
    return out
