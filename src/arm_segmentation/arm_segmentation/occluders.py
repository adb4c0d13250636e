"""Objects nearer than the depth sensor's minimum range (a camera held just above the table).

Such an object returns no depth at all, so it never rises above a support plane. It shows as a
large region without depth where the table, seen from this pose, would have been measured: the
viewing ray meets the support level between the camera and its visible footprint, within the
sensor's range and not at a grazing angle. Large such regions whose colour is not the table's
become instances (one per connected region).
"""

from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage

from arm_core.camera import ray_directions_world
from arm_core.vectors import vector_length
from arm_segmentation.clustering import chromaticity, hue_distance
from arm_segmentation.table_plane import SupportLevel, extend_towards


@dataclass(frozen=True)
class OccluderParams:
    """Parameters of near-range occluder detection (metres; fractions of the working grid)."""

    enabled: bool = True
    min_table_range_m: float = 0.15  # the table would be measured from here on...
    max_table_range_m: float = 2.5  # ...up to here
    min_cos_incidence: float = 0.3  # rays flatter than this over the table may lose returns anyway
    footprint_margin_m: float = 0.03
    min_fraction: float = 0.02  # smallest region, fraction of the image
    open_px: int = 2  # opening radius that removes dropout lines along depth edges
    table_colour_threshold: float = 0.1
    min_off_table_colour: float = 0.6  # fraction of the region whose colour is not the table's


def expected_table(ys, xs, K: np.ndarray, T: np.ndarray, level: SupportLevel, params: OccluderParams) -> np.ndarray:
    """(N,) bool for pixels (ys, xs): their ray meets the level's plane within range, inside the
    convex hull of its visible footprint and the camera's position (the occluder hides the table
    nearest to it)."""
    direction = ray_directions_world(ys, xs, K, T)
    dz = direction[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = np.float32(level.height_m - T[2, 3]) / dz
    cos_incidence = np.abs(dz) / vector_length(direction)
    ok = (dz < 0) & (depth >= params.min_table_range_m) & (depth <= params.max_table_range_m)
    ok &= cos_incidence >= params.min_cos_incidence
    hit = T[:2, 3].astype(np.float32) + direction[:, :2] * np.where(ok, depth, 0.0)[:, None]
    return ok & extend_towards(level, T[:2, 3]).contains_xy(hit, params.footprint_margin_m)


def near_occluders(taken, depth_m, rgb, table, K, T, levels, params: OccluderParams) -> np.ndarray:
    """Instance labels (int64, 0 = none) of the near-range occluders outside `taken` pixels."""
    none = np.zeros(depth_m.shape, dtype=np.int64)
    min_px = params.min_fraction * depth_m.size
    missing = (depth_m <= 0) & ~taken
    if not params.enabled or not levels or missing.sum() < min_px or not np.any(table):
        return none
    ys, xs = np.nonzero(missing)
    missing[ys, xs] = expected_table(ys, xs, K, T, levels[0], params)
    if missing.sum() < min_px:
        return none
    r = params.open_px
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    missing = cv2.morphologyEx(missing.astype(np.uint8), cv2.MORPH_OPEN, disk) > 0
    regions, n = ndimage.label(missing)
    if n == 0:
        return none
    chroma = chromaticity(rgb)
    table_chroma = np.median(chroma[table][:: max(1, int(table.sum()) // 5000)], axis=0)
    off_table = hue_distance(chroma, table_chroma) > params.table_colour_threshold
    size = np.bincount(regions.ravel(), minlength=n + 1)
    off = np.bincount(regions.ravel(), weights=off_table.ravel(), minlength=n + 1)
    keep = (size >= min_px) & (off >= params.min_off_table_colour * size)
    keep[0] = False
    new_ids = np.zeros(n + 1, dtype=np.int64)
    new_ids[keep] = np.arange(1, int(keep.sum()) + 1)
    return np.where(off_table, new_ids[regions], 0)
