"""Gravity-aligned support-plane estimation: the table (and any further horizontal table levels).

The world frame is gravity-aligned (+z up), so every support plane is z = h. Levels are found as
area-weighted peaks in the height histogram of upward-facing pixels; each level's footprint is the
convex hull of its inlier pixels in the xy plane.
"""

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import ConvexHull, QhullError

from arm_core.settings import setting
from arm_core.vectors import vector_length


@dataclass(frozen=True)
class TableParams:
    """Parameters of support-level estimation (metres, degrees)."""

    horizontal_tolerance_deg: float = 12.0
    histogram_bin_m: float = 0.004
    # a camera 0.2 m above the table sees about 0.07 m^2 of it past the objects
    min_table_area_m2: float = setting(
        0.05, "Smallest horizontal plane taken as a table, m^2", 0.005, 10.0, parameter=True
    )
    # a close-up sees less than min_table_area_m2 in all (0.04 m^2 from 0.4 m at fx 1067 px): there a
    # plane covering this share of the surface seen is a table too
    min_table_view_share: float = 0.15
    max_levels: int = 3
    band_m: float = 0.006
    band_per_m2: float = 0.003
    footprint_margin_m: float = 0.03
    max_object_height_m: float = setting(0.6, "Tallest object above its table, m", 0.02, 3.0, parameter=True)
    # an instance with less than this share of its points over a support's footprint stands beside
    # the table, not on it (a wall behind it, furniture past its edge)
    min_share_over_support: float = 0.5


@dataclass(frozen=True)
class SupportLevel:
    """One horizontal support plane z = height_m with its footprint (convex hull in world xy)."""

    height_m: float
    area_m2: float
    hull_equations: np.ndarray  # (F, 3): inside where eq[:, :2] @ xy + eq[:, 2] <= 0 (unit normals)
    hull_xy: np.ndarray  # (M, 2) hull vertices, counter-clockwise
    pixels: int = 0  # inlier pixels in the image

    def contains_xy(self, xy: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
        """Boolean (...,) whether points (..., 2) lie inside the footprint grown by margin_m."""
        eq = self.hull_equations.astype(np.float32)
        inside = np.ones(xy.shape[:-1], dtype=bool)
        for a, b, c in eq:
            inside &= a * xy[..., 0] + b * xy[..., 1] + (c - margin_m) <= 0.0
        return inside


def pixel_area_m2(points_camera: np.ndarray, normals_camera: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Approximate surface area (m^2) that each pixel covers, from depth and viewing incidence."""
    z = points_camera[..., 2]
    dist = vector_length(points_camera)
    cos_incidence = np.abs(np.einsum("hwc,hwc->hw", normals_camera, points_camera)) / np.maximum(dist, 1e-6)
    return (z * z / (K[0, 0] * K[1, 1])) / np.maximum(cos_incidence, 0.25)


def band_for_depth(depth_m: np.ndarray, params: TableParams) -> np.ndarray:
    """Half-width of the table inlier band (m), growing with depth like structured-light noise."""
    return params.band_m + params.band_per_m2 * depth_m * depth_m


def estimate_support_levels(
    points_world: np.ndarray,
    normals_world: np.ndarray,
    area_m2: np.ndarray,
    valid: np.ndarray,
    params: TableParams = TableParams(),
) -> list[SupportLevel]:
    """Find up to params.max_levels horizontal support planes, largest first.

    points_world, normals_world: HxWx3 (world frame, +z up); area_m2, valid: HxW.
    Returns an empty list when no upward-facing plane of at least min_table_area(area_m2[valid]) is seen.
    """
    min_area_m2 = min_table_area(area_m2[valid], params)
    cos_tol = np.cos(np.deg2rad(params.horizontal_tolerance_deg))
    up = valid & (normals_world[..., 2] >= cos_tol)
    if not np.any(up):
        return []
    up_y, up_x = np.nonzero(up)
    z = points_world[..., 2][up].astype(np.float64)
    w = area_m2[up].astype(np.float64)
    xy = points_world[..., :2][up]
    lo, hi = float(z.min()), float(z.max())
    n_bins = max(int(np.ceil((hi - lo) / params.histogram_bin_m)) + 1, 1)
    hist = np.bincount(((z - lo) / params.histogram_bin_m).astype(np.int64), weights=w, minlength=n_bins)
    half = max(int(round(params.band_m / params.histogram_bin_m)), 1)
    window = np.convolve(hist, np.ones(2 * half + 1))[half : half + n_bins]
    levels: list[SupportLevel] = []
    taken = np.zeros(n_bins, dtype=bool)
    for peak in np.argsort(window)[::-1]:
        if len(levels) >= params.max_levels or window[peak] < min_area_m2:
            break
        if taken[peak]:
            continue
        first = max(peak - half, 0)
        peak = first + int(np.argmax(hist[first : peak + half + 1]))
        taken[max(peak - 3 * half, 0) : peak + 3 * half + 1] = True
        centre = lo + (peak + 0.5) * params.histogram_bin_m
        near = np.abs(z - centre) <= (half + 0.5) * params.histogram_bin_m
        if not np.any(near):
            continue
        height = _weighted_median(z[near], w[near])
        in_band = valid & (np.abs(points_world[..., 2] - height) <= params.band_m)
        inliers = _coherent(np.abs(z - height) <= params.band_m, up_y, up_x, w, in_band, min_area_m2)
        area = float(w[inliers].sum())
        if area < min_area_m2:
            continue
        hull = _hull(xy[inliers])
        if hull is None:
            continue
        levels.append(SupportLevel(float(height), area, hull[0], hull[1], int(np.count_nonzero(inliers))))
    return levels


def min_table_area(seen_area_m2: np.ndarray, params: TableParams) -> float:
    """Smallest plane (m^2) taken as a table in a view whose pixels with depth cover seen_area_m2:
    min_table_area_m2, or min_table_view_share of all the view sees where that is less (a close-up)."""
    return min(params.min_table_area_m2, params.min_table_view_share * float(np.sum(seen_area_m2)))


def workspace_levels(levels: list[SupportLevel], params: TableParams = TableParams()) -> list[SupportLevel]:
    """The levels objects may rest on: the level seen in most pixels (the table the camera looks
    at) and the higher levels standing on it (centre of their footprint inside the table's). Lower
    levels (the floor seen past the table's edge, a lower second table) and higher levels beside
    the table (other furniture) carry no objects, so their legs, edges and clutter are never
    instances."""
    if not levels:
        return levels
    levels = sorted(levels, key=lambda level: -level.pixels)  # far surfaces (the floor) have large m^2
    table = levels[0]
    higher = [
        level
        for level in levels[1:]
        if level.height_m > table.height_m + params.band_m
        and table.contains_xy(level.hull_xy.mean(axis=0), params.footprint_margin_m)
    ]
    return [table, *higher]


def extend_towards(level: SupportLevel, xy) -> SupportLevel:
    """The level with its footprint grown to the convex hull of the footprint and the point xy.

    Seen from a camera at xy, the part of the table nearest to it is often hidden by the objects
    standing there or cut off by the image border; they still stand on it.
    """
    hull = _hull(np.vstack([level.hull_xy, np.asarray(xy, dtype=np.float64).reshape(1, 2)]))
    if hull is None:
        return level
    return SupportLevel(level.height_m, level.area_m2, hull[0], hull[1], level.pixels)


def support_heights(
    points_world: np.ndarray,
    depth_m: np.ndarray,
    levels: list[SupportLevel],
    params: TableParams = TableParams(),
) -> np.ndarray:
    """HxW float32 height (m) of the support level under each pixel; NaN where there is none.

    A pixel belongs to the highest level whose footprint contains it and that lies below it.
    Pixels without depth take the support of the nearest pixel with depth.
    """
    valid = depth_m > 0
    support = np.full(depth_m.shape, np.nan, dtype=np.float32)
    if not levels:
        return support
    z = points_world[..., 2]
    band = band_for_depth(depth_m, params)
    for level in sorted(levels, key=lambda lv: lv.height_m):
        above = valid & (z >= level.height_m - band)
        ys, xs = np.nonzero(above)
        inside = level.contains_xy(points_world[ys, xs, :2], params.footprint_margin_m)
        support[ys[inside], xs[inside]] = level.height_m
    if np.any(valid) and not np.all(valid):
        _, (iy, ix) = ndimage.distance_transform_edt(~valid, return_indices=True)
        support = np.where(valid, support, support[iy, ix])
    return support


def classify_heights(
    z_world: np.ndarray, depth_m: np.ndarray, support: np.ndarray, params: TableParams = TableParams()
) -> tuple[np.ndarray, np.ndarray]:
    """(table_mask, object_mask) of the pixels with depth: table within the depth-dependent band
    of their support level, object up to max_object_height_m above it, else background."""
    has_support = (depth_m > 0) & ~np.isnan(support)
    height = np.where(has_support, z_world - np.nan_to_num(support), np.inf)
    band = band_for_depth(depth_m, params)
    table = has_support & (height <= band)
    objects = has_support & (height > band) & (height <= params.max_object_height_m)
    return table, objects


def classify_points(
    points_world: np.ndarray,
    depth_m: np.ndarray,
    levels: list[SupportLevel],
    params: TableParams = TableParams(),
) -> tuple[np.ndarray, np.ndarray]:
    """Split valid pixels into (table_mask, object_mask), both HxW bool (see classify_heights)."""
    support = support_heights(points_world, depth_m, levels, params)
    return classify_heights(points_world[..., 2], depth_m, support, params)


def _coherent(inliers, ys, xs, weights, in_band, min_area_m2: float) -> np.ndarray:
    """Keep the inliers that belong to large connected regions of the image.

    A plane seen as many small patches at one height (the tops of equal boxes) is no table: the
    largest region must reach min_area_m2, and only regions of at least a tenth of that take part
    in the footprint. Regions are connected through every pixel at the level's height (in_band, HxW
    bool), also where noisy normals do not face up: a real sensor's table is one region, not specks.
    """
    image = np.zeros(in_band.shape, dtype=bool)
    image[ys[inliers], xs[inliers]] = True
    regions, n = ndimage.label(image | in_band, structure=np.ones((3, 3), bool))
    if n == 0:
        return np.zeros_like(inliers)
    region_of = regions[ys, xs]
    region_area = np.bincount(region_of, weights=np.where(inliers, weights, 0.0), minlength=n + 1)
    region_area[0] = 0.0
    if region_area.max() < min_area_m2:
        return np.zeros_like(inliers)
    return inliers & (region_area[region_of] >= 0.1 * min_area_m2)


def _weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cumulative, 0.5 * cumulative[-1])])


def _hull(xy: np.ndarray, max_points: int = 4000):
    if len(xy) < 3:
        return None
    if len(xy) > max_points:
        xy = xy[np.linspace(0, len(xy) - 1, max_points).astype(np.int64)]
    try:
        hull = ConvexHull(xy.astype(np.float64))
    except QhullError:
        return None
    return hull.equations.copy(), xy[hull.vertices].astype(np.float64)
