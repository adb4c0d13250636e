"""Overhangs: instances that could not stay where they are seen, so are parts of the object they touch.

A jug's handle standing off its side, or a drill's chuck sticking out over the table, comes out as an
instance of its own when a depth edge or a colour change cuts it from its object. Such a part rests on
nothing: below it, down to its support, the camera sees through to the table or the room beyond, and
it touches the object that carries it at that object's depth. An instance is an overhang when
- its lowest points (the low_percentile of its heights) are more than min_height_m above its support;
- of the points sampled every sample_step_m below its points, down to the support, at least
  min_free_share are seen empty: the camera's depth at their pixel lies more than free_margin_m
  beyond them; and at most max_rest_share lie on the seen surface of a third instance (one it could
  rest on: a lamp's shade over its stem, when the stem is an instance of its own);
- at least min_contact_share of its outline runs along a larger instance at its depth
  (fragments.contact_counts), and that contact runs up its side: the 10th percentile of the
  contact's heights lies below side_share of the way from the instance's low_percentile height to its
  (100 - low_percentile) one, the 90th above it.
It joins the larger instance it touches most. A box stacked on another, or one seen above a nearer
object, stays apart: the space under it lies inside the object under it or behind the nearer one, where
the camera cannot see it empty (on the OSD frames no such instance reached 0.36; the handles and
chucks of the household frames, and a bowl's rim on OSD, 0.50-0.67). So does a part that the other
touches only along its bottom edge, resting on it (a lamp's shade over a stem that went to the object
behind it), or only along its top, lying under it (an object mostly hidden under another that leans
on it).
"""

from dataclasses import dataclass

import numpy as np

from arm_core.boxes import cropped_intrinsics, mask_box
from arm_core.camera import backproject_pixels, project_points
from arm_segmentation.fragments import (
    FragmentParams,
    contact_counts,
    join_into_owners,
    touching_pixels,
    visible_areas_m2,
)
from arm_segmentation.table_plane import SupportLevel


@dataclass(frozen=True)
class OverhangParams:
    min_height_m: float = 0.03  # the instance's low_percentile height above its support
    low_percentile: float = 10.0
    min_free_share: float = 0.45  # of the samples below the instance, seen empty
    max_rest_share: float = 0.03  # of the samples below it, on a third instance's surface
    min_contact_share: float = 0.1  # of its outline pixel pairs, along the larger instance it joins
    side_share: float = 0.5  # of its height range, that the contact reaches below and above
    sample_step_m: float = 0.01
    free_margin_m: float = 0.01  # the depth seen at a sample's pixel lies this far beyond it: empty
    columns: int = 300  # points of the instance whose columns below are sampled


def support_height_m(heights_m: np.ndarray, xy_m: np.ndarray, levels: list[SupportLevel]) -> float:
    """The height (world z, m) of the support under points: the highest level below their lowest
    heights (heights_m: the points' world z) whose footprint holds their median xy; the first level
    when none does."""
    low = float(np.min(heights_m))
    centre = np.median(xy_m, axis=0)
    under = [lv.height_m for lv in levels if lv.height_m <= low + 0.01 and bool(lv.contains_xy(centre, 0.05))]
    return max(under) if under else float(levels[0].height_m)


@dataclass
class SpaceBelow:
    """What the camera sees of the points sampled below an instance: `sampled` of them, `empty` seen
    empty (the depth at their pixel beyond them by free_margin_m), and, of those on a seen surface
    (within free_margin_m of it), `on_labels`: the instance labels of those surfaces' pixels."""

    sampled: int
    empty: int
    on_labels: np.ndarray


def space_below(points_world: np.ndarray, support_m: float, labels, depth_m, K, T_world_camera, params: OverhangParams):
    """SpaceBelow of the points every sample_step_m below points_world (N, 3), down to support_m +
    sample_step_m. Samples outside the image or on pixels without depth are neither empty nor on a
    surface."""
    drops = np.arange(params.sample_step_m, 1.0, params.sample_step_m)
    drops = drops[drops < float(points_world[:, 2].max() - support_m) - params.sample_step_m]
    samples = np.repeat(points_world[:, None, :], len(drops), axis=1)
    samples[..., 2] -= drops[None, :]
    samples = samples[samples[..., 2] > support_m + params.sample_step_m]
    if len(samples) == 0:
        return SpaceBelow(0, 0, np.zeros(0, dtype=labels.dtype))
    uv, depth_along_ray = project_points(samples, K, T_world_camera)
    height, width = depth_m.shape
    u, v = np.floor(uv[:, 0]).astype(np.int64), np.floor(uv[:, 1]).astype(np.int64)
    inside = (u >= 0) & (u < width) & (v >= 0) & (v < height) & (depth_along_ray > 0)
    u, v, depth_along_ray = u[inside], v[inside], depth_along_ray[inside]
    seen = depth_m[v, u]
    empty = int(np.count_nonzero(seen > depth_along_ray + params.free_margin_m))
    on_surface = (seen > 0) & (np.abs(seen - depth_along_ray) <= params.free_margin_m)
    return SpaceBelow(len(samples), empty, labels[v[on_surface], u[on_surface]])


def instance_points(labels: np.ndarray, depth_m: np.ndarray, K: np.ndarray, T_world_camera: np.ndarray):
    """(flat pixel indices, labels, world points (N, 3) m) of the instance pixels with depth, ordered by
    label."""
    flat = np.flatnonzero((labels > 0) & (depth_m > 0))
    flat = flat[np.argsort(labels.ravel()[flat], kind="stable")]
    v, u = np.divmod(flat, labels.shape[1])
    return flat, labels.ravel()[flat], backproject_pixels(depth_m, v, u, K, T_world_camera)


def join_overhangs(labels, depth_m, K, T_world_camera, levels: list[SupportLevel], params: OverhangParams):
    """Labels with each overhang (module docstring) given to the larger instance it touches most;
    renumbered 1..N in the order of the original ids."""
    n = int(labels.max())
    if n < 2 or not levels:
        return labels
    contact = FragmentParams()
    crop = mask_box(labels > 0, contact.contact_reach_px + 1)
    sub_labels, sub_depth, K_crop = labels[crop], depth_m[crop], cropped_intrinsics(K, crop)
    flat, point_labels, points = instance_points(sub_labels, sub_depth, K_crop, T_world_camera)
    starts = np.searchsorted(point_labels, np.arange(1, n + 2))
    heights_m = np.zeros(sub_labels.size)
    heights_m[flat] = points[:, 2]
    areas = visible_areas_m2(sub_labels, sub_depth, K_crop)
    touching = outline = None
    owner = np.arange(n + 1)
    for i in range(1, n + 1):
        mine = points[starts[i - 1] : starts[i]]
        if len(mine) < 10:
            continue
        support_m = support_height_m(mine[:, 2], mine[:, :2], levels)
        low_m, high_m = np.percentile(mine[:, 2], [params.low_percentile, 100.0 - params.low_percentile])
        if low_m - support_m <= params.min_height_m:
            continue
        if touching is None:
            touching, outline = contact_counts(sub_labels, sub_depth, contact)
            touching[:, 0] = 0
        larger = np.where(areas > areas[i], touching[i], 0)
        if larger.max() < params.min_contact_share * max(outline[i], 1):
            continue
        columns = mine[np.linspace(0, len(mine) - 1, min(params.columns, len(mine))).astype(np.int64)]
        below = space_below(columns, support_m, labels, depth_m, K, T_world_camera, params)
        if not below.sampled or below.empty < params.min_free_share * below.sampled:
            continue
        j = int(np.argmax(larger))
        on_others = np.count_nonzero((below.on_labels != i) & (below.on_labels != j) & (below.on_labels > 0))
        if on_others > params.max_rest_share * below.sampled:
            continue  # a third instance's surface right below it: it may rest on that
        contact_heights_m = heights_m[touching_pixels(sub_labels, sub_depth, i, j, contact)]
        contact_low_m, contact_high_m = np.percentile(contact_heights_m, [10, 90])
        middle_m = low_m + params.side_share * (high_m - low_m)
        if contact_low_m <= middle_m <= contact_high_m:
            owner[i] = j
    return labels if np.array_equal(owner, np.arange(n + 1)) else join_into_owners(labels, owner)
