"""Default unseen-object instance segmentation: support planes, then 3D instance clustering.

`segment(rgb, depth_m, K, T_world_camera)` needs no learned weights and runs on the CPU.
"""

import functools
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from arm_core.boxes import cropped_intrinsics, mask_box, resized_intrinsics
from arm_core.camera import backproject_image, backproject_pixels, organized_normals, transform_points
from arm_core.frames import FrameInputError, validate_frame
from arm_core.settings import setting
from arm_segmentation.boundary import (
    BorderParams,
    grow_into_objectness,
    nearest_pixel,
    refine_borders,
)
from arm_segmentation.boundary_net import BoundaryParams, boundary_features, shared_predictor
from arm_segmentation.clustering import ClusterParams, chromaticity, cluster_instances, hue_distance
from arm_segmentation.fragments import FragmentParams, absorb_fragments
from arm_segmentation.geometry import preprocess_depth
from arm_segmentation.label_stats import label_maximum
from arm_segmentation.merge_model import LearnedMerge, MergeParams, pixel_statistics, shared_classifier
from arm_segmentation.occluders import OccluderParams, expected_table, near_occluders
from arm_segmentation.outline_model import OutlineParams, refine_outline, shared_outline_classifier
from arm_segmentation.overhangs import OverhangParams, join_overhangs
from arm_segmentation.refine import RefineParams, instance_colours, refine_full_resolution, upsample, upsample_linear
from arm_segmentation.table_plane import (
    SupportLevel,
    TableParams,
    band_for_depth,
    classify_heights,
    estimate_support_levels,
    extend_towards,
    pixel_area_m2,
    support_heights,
    workspace_levels,
)


@dataclass(frozen=True)
class FineParams:
    """Full-resolution clustering on a crop around the objects (pixel sizes at full resolution).

    The pixel-based clustering parameters replace those of SegmentationParams.cluster there.
    """

    max_pixels: int = 150_000  # larger crops are clustered on the working grid
    margin_px: int = 12
    candidate_radius_px: int = 4
    missing_candidate_radius_px: int = 8  # pixels without depth (dark, shiny surfaces) reach further
    table_colour_window_px: int = 31
    step_px: int = 3
    contact_radius_px: int = 3
    small_fragment_px: int = 200
    min_contact_px: int = 6
    min_fragment_px: int = 6
    flood_iterations: int = 24
    grow_radius_px: int = 3

    def cluster_params(self, cluster: ClusterParams) -> ClusterParams:
        names = ("step_px", "contact_radius_px", "small_fragment_px", "min_contact_px", "min_fragment_px")
        names += ("flood_iterations", "grow_radius_px")
        return replace(cluster, **{name: getattr(self, name) for name in names})


NETWORK_MARGIN_PX = 24  # working-grid context the boundary network sees around the object pixels


@dataclass(frozen=True)
class SegmentationParams:
    """All parameters of the default method. Pixel sizes refer to the working resolution: the
    input subsampled by working_stride (2: a 640x480 frame is processed at 320x240)."""

    working_stride: int = setting(2, "Subsampling of the working grid (1: full resolution)", 1, 4)
    # the image size the pixel sizes below were chosen at; frames far larger are subsampled towards it
    reference_pixels: int = 640 * 480

    fill_radius_px: int = 1
    missing_rim_close_px: int = 4  # full-resolution pixels (trim_missing_rim)
    rim_window_px: int = 41  # full-resolution pixels: wider than a projector's shadow beside a near object
    grown_on_support_m: float = 0.005  # grown pixels this near a support level pass the colour test
    fill_enclosed_missing: bool = True
    fill_closed_missing_px: int = 6  # pixels without depth in this closing of the instances join them (0: off)
    smooth_sigma_m: float = 0.01
    table_colour_threshold: float = 0.1
    candidate_radius_px: int = 4
    table_colour_window_px: int = 15
    missing_candidate_radius_px: int = 4
    extend_table_to_camera: bool = True  # the largest level's footprint reaches under the camera
    table: TableParams = field(default_factory=TableParams)
    cluster: ClusterParams = field(default_factory=ClusterParams)
    refine: RefineParams = field(default_factory=RefineParams)
    fine: FineParams = field(default_factory=FineParams)
    occluders: OccluderParams = field(default_factory=OccluderParams)
    border: BorderParams = field(default_factory=BorderParams)
    boundary: BoundaryParams = field(default_factory=BoundaryParams)
    merge: MergeParams = field(default_factory=MergeParams)
    outline: OutlineParams = field(default_factory=OutlineParams)
    fragments: FragmentParams = field(default_factory=FragmentParams)
    overhangs: OverhangParams = field(default_factory=OverhangParams)


@dataclass
class SegmentationResult:
    labels: np.ndarray  # uint16 HxW, 0 = table / background, k > 0 = instance k
    table_mask: np.ndarray  # bool HxW
    levels: list[SupportLevel]
    # HxW float32 object probability of the boundary network at full resolution (None without it)
    objectness: np.ndarray | None = None
    empty_reason: str = ""  # why there is no instance ('' when there is one)


def empty_reason(labels: np.ndarray, levels: list[SupportLevel], params: SegmentationParams) -> str:
    """Why a frame gave no instance, in words a user can act on ('' when it gave one)."""
    if np.any(labels):
        return ""
    if not levels:
        return (
            f"no support: no horizontal surface of at least {params.table.min_table_area_m2} m^2 (or "
            f"{params.table.min_table_view_share:.0%} of what the camera sees) is seen under this camera pose (is "
            "T_world_camera's z up, and is the table in view?)"
        )
    return (
        f"nothing stands on the support at {levels[0].height_m:+.3f} m: no object between the table band and "
        f"{params.table.max_object_height_m} m above it"
    )


def local_table_chroma(chroma: np.ndarray, table: np.ndarray, window_px: int) -> np.ndarray:
    """HxWx3 mean chromaticity of the table pixels around each pixel (the global median where none).

    Table colour varies with lighting (glare, saturation), so candidates are compared locally.
    """
    weight = table.astype(np.float32)
    ksize = (window_px, window_px)
    count = cv2.boxFilter(weight, -1, ksize, normalize=False)
    total = cv2.boxFilter(chroma * weight[..., None], -1, ksize, normalize=False)
    fallback = np.median(chroma[table][:: max(1, int(table.sum()) // 5000)], axis=0)
    return np.where(count[..., None] > 0.5, total / np.maximum(count, 1.0)[..., None], fallback).astype(np.float32)


@dataclass
class _Stage:
    """Everything computed on one grid (the working grid, or a full-resolution crop of it)."""

    smoothed: np.ndarray
    points_camera: np.ndarray
    normals_camera: np.ndarray
    valid: np.ndarray
    points_world: np.ndarray
    area: np.ndarray
    support: np.ndarray
    table: np.ndarray
    objects: np.ndarray
    levels: list[SupportLevel]
    chroma: np.ndarray | None = None
    candidates: np.ndarray | None = None
    table_chroma: np.ndarray | None = None


def _geometry(depth, K, T, params: SegmentationParams, step_px: int, levels, support=None) -> _Stage:
    """Points, normals, support levels (estimated unless given), support heights (computed unless
    given), table and object masks."""
    smoothed = preprocess_depth(depth, params.fill_radius_px, params.smooth_sigma_m)
    points_camera = backproject_image(smoothed, K)
    normals_camera = organized_normals(points_camera, step_px)
    valid = normals_camera[..., 2] != 0
    points_world = transform_points(points_camera, T)
    area = pixel_area_m2(points_camera, normals_camera, K)
    area[~valid] = 0.0
    if levels is None:
        normals_world = normals_camera @ T[:3, :3].T.astype(np.float32)
        levels = workspace_levels(estimate_support_levels(points_world, normals_world, area, valid, params.table))
        if levels and params.extend_table_to_camera:
            levels[0] = extend_towards(levels[0], T[:2, 3])
    if support is None:
        support = support_heights(points_world, smoothed, levels, params.table)
    table, objects = classify_heights(points_world[..., 2], smoothed, support, params.table)
    return _Stage(smoothed, points_camera, normals_camera, valid, points_world, area, support, table, objects, levels)


def missing_over_table(depth_m, K, T, levels, params: OccluderParams) -> np.ndarray:
    """HxW bool: pixels without depth whose viewing ray meets the table inside its footprint.

    Only there can a missing return be an object (dark, shiny) standing on the table; elsewhere it
    is the background beyond the sensor's range."""
    out = np.zeros(depth_m.shape, dtype=bool)
    ys, xs = np.nonzero(depth_m <= 0)
    if levels and len(ys):
        out[ys, xs] = expected_table(ys, xs, K, T, levels[0], params)
    return out


def _near(mask: np.ndarray, radius_px: int) -> np.ndarray:
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius_px + 1, 2 * radius_px + 1))
    return cv2.dilate(mask.astype(np.uint8), disk) > 0


def _colour(stage: _Stage, rgb, K, T, params: SegmentationParams, window_px: int, radii_px: tuple[int, int]) -> _Stage:
    """Adds chromaticity, the local table colour and the candidate mask (pixels in the table band
    within radii_px[0] of objects, or without depth over the table within radii_px[1], whose colour
    is not the table's)."""
    stage.chroma = chromaticity(rgb)
    stage.candidates = np.zeros_like(stage.objects)
    if np.any(stage.table) and np.any(stage.objects):
        stage.table_chroma = local_table_chroma(stage.chroma, stage.table, window_px)
        not_table_colour = hue_distance(stage.chroma, stage.table_chroma) > params.table_colour_threshold
        missing = missing_over_table(stage.smoothed, K, T, stage.levels, params.occluders)
        in_band = stage.table & _near(stage.objects, radii_px[0])
        stage.candidates = not_table_colour & (in_band | (missing & _near(stage.objects, radii_px[1])))
    return stage


def _cluster(stage: _Stage, cluster: ClusterParams, params: SegmentationParams, scorer=None):
    """scorer: None, or the learned merging on stage's grid (merge_scorer)."""
    labels = cluster_instances(
        stage.points_camera, stage.normals_camera, stage.smoothed, stage.chroma, stage.objects, stage.candidates,
        stage.valid, stage.area, stage.table_chroma, cluster, stage.points_world[..., 2] - stage.support, scorer,
    )  # fmt: skip
    return drop_support_structure(labels, stage.points_world, stage.smoothed, stage.support, stage.levels, params.table)


def merge_scorer(stage: _Stage, rgb, outline, cluster: ClusterParams, grid, params: SegmentationParams, factory=None):
    """The learned merging (merge_model.LearnedMerge) on stage's grid, or None without the boundary
    network's outline map or the classifier's weights. grid: (rows, cols) slices of the full frame
    that stage covers. factory(grid, stats, height_m, outline, cluster) replaces the
    classifier (seg_merge_train's oracle)."""
    if outline is None:
        return None
    if factory is None:
        classifier = shared_classifier(params.merge)
        if classifier is None:
            return None

        def factory(_, *args):
            return LearnedMerge(classifier, *args, threshold=params.merge.threshold)

    stats = pixel_statistics(stage.chroma, rgb, stage.normals_camera, np.where(stage.objects, stage.area, 0.0))
    height_m = np.where(stage.objects & stage.valid, stage.points_world[..., 2] - stage.support, np.nan)
    return factory(grid, stats, height_m, outline, cluster)


def fine_crop(objects: np.ndarray, stride: int, shape: tuple[int, int], fine: FineParams):
    """Full-resolution (rows, cols) slices around the working-grid object pixels, or None when
    there are none or the crop would exceed fine.max_pixels."""
    crop = mask_box(objects, fine.margin_px, stride, shape)
    if crop is None or (crop[0].stop - crop[0].start) * (crop[1].stop - crop[1].start) > fine.max_pixels:
        return None
    return crop


def _upsampled_crop(image: np.ndarray, crop, stride: int, full_shape) -> np.ndarray:
    """The full-resolution crop (rows, cols slices) of a working-grid image, upsampled."""
    y0, x0 = crop[0].start, crop[1].start
    full = upsample(image[y0 // stride :, x0 // stride :], stride, full_shape)
    return full[y0 % stride :, x0 % stride :][: crop[0].stop - y0, : crop[1].stop - x0]


def working_stage(rgb_full, depth_full, K_full, T, params: SegmentationParams):
    """(rgb, depth, K, stage) on the working grid (every working_stride-th pixel) of a validated frame."""
    stride = params.working_stride
    rgb, depth, K = rgb_full, depth_full, K_full
    if stride > 1:
        rgb, depth = rgb_full[::stride, ::stride], depth_full[::stride, ::stride]
        K = K_full.copy()
        K[:2] /= stride
    return rgb, depth, K, _geometry(depth, K, T, params, params.cluster.step_px, None)


def stage_features(rgb: np.ndarray, stage: _Stage) -> np.ndarray:
    """The boundary network's input for a working-grid stage."""
    return boundary_features(rgb, stage.smoothed, stage.normals_camera, stage.points_world[..., 2] - stage.support)


def learned_maps(rgb: np.ndarray, stage: _Stage, params: BoundaryParams) -> np.ndarray | None:
    """(2, H, W) float32 working-grid probabilities from the boundary network: that a pixel lies
    where two objects meet, and that it is on an object; None without the network (not used by
    params, or no weights) or without object pixels. The network sees the object pixels' bounding
    box grown by NETWORK_MARGIN_PX (its sides multiples of 8); outside it both are 0."""
    predictor = shared_predictor(params)
    if predictor is None or not np.any(stage.objects):
        return None
    ys, xs = np.nonzero(stage.objects)
    height, width = stage.objects.shape
    y0, x0 = max(int(ys.min()) - NETWORK_MARGIN_PX, 0), max(int(xs.min()) - NETWORK_MARGIN_PX, 0)
    y1 = min(y0 + -(-(int(ys.max()) + NETWORK_MARGIN_PX + 1 - y0) // 8) * 8, height)
    x1 = min(x0 + -(-(int(xs.max()) + NETWORK_MARGIN_PX + 1 - x0) // 8) * 8, width)
    maps = np.zeros((2, height, width), dtype=np.float32)
    maps[:, y0:y1, x0:x1] = predictor.predict(stage_features(rgb, stage)[:, y0:y1, x0:x1])
    return maps


def segment_detailed(
    rgb, depth_m, K, T_world_camera, params: SegmentationParams | None = None, exclude=None, merge_factory=None
):  # fmt: skip
    """Segment one frame; also returns the table mask and the support levels found.

    exclude: optional HxW bool, pixels that are never objects (the robot's own arm, self_filter):
    they are treated as having no depth and are cleared from the labels. merge_factory: replaces
    the merge classifier (merge_scorer; for training it).

    The pixel sizes of params hold at params.reference_pixels: a larger frame (a 1280x720 camera) is
    segmented subsampled by a whole factor towards it (reference_factor), and its results are
    resampled back, the outlines decided anew by colour at the frame's resolution.
    Support levels are always estimated on the working grid. When the objects fit in a crop of at
    most params.fine.max_pixels full-resolution pixels, they are clustered on that crop at full
    resolution (small, distant objects keep their depth edges); otherwise on the working grid,
    refined to full resolution afterwards.

    Raises arm_core.frames.FrameInputError for frames that cannot be interpreted (shapes, intrinsics, pose).
    A frame without a visible table gives an all-zero label image.
    """
    params = params or SegmentationParams()
    frame = validate_frame(depth_m, K, T_world_camera, rgb=rgb)
    if exclude is not None:
        exclude = np.asarray(exclude, dtype=bool)
        if exclude.shape != frame.depth_m.shape:
            raise FrameInputError(f"exclude mask has shape {exclude.shape}, the depth image {frame.depth_m.shape}")
    factor = reference_factor(frame.depth_m.shape, params.reference_pixels)
    if factor == 1:
        return _segment(frame.rgb, frame.depth_m, frame.K, frame.T_world_camera, params, exclude, merge_factory)
    shape = (frame.depth_m.shape[0] // factor, frame.depth_m.shape[1] // factor)
    nearest = functools.partial(_resample, shape=shape, interpolation=cv2.INTER_NEAREST_EXACT)
    colour = _resample(frame.rgb, shape, cv2.INTER_AREA)
    K_resampled = resized_intrinsics(frame.K, frame.depth_m.shape, shape)
    small_exclude = None if exclude is None else nearest(exclude.astype(np.uint8)) > 0
    result = _segment(
        colour, nearest(frame.depth_m), K_resampled, frame.T_world_camera, params, small_exclude, merge_factory
    )
    back = functools.partial(_resample, shape=frame.depth_m.shape, interpolation=cv2.INTER_NEAREST_EXACT)
    labels = refine_borders(back(result.labels), frame.rgb, params.border)
    if exclude is not None and np.any(labels[exclude]):
        labels = _renumber(np.where(exclude, 0, labels))
    objectness = None
    if result.objectness is not None:
        objectness = _resample(result.objectness, frame.depth_m.shape, cv2.INTER_LINEAR)
    table = back(result.table_mask.astype(np.uint8)) > 0
    return SegmentationResult(labels, table, result.levels, objectness, result.empty_reason)


def reference_factor(shape: tuple[int, int], reference_pixels: int) -> int:
    """The whole factor that brings an image of shape (rows, cols) nearest to reference_pixels pixels
    from above, 1 within a factor of 1.5 in side length of it (848x480 stays as it is; 1280x720 and
    1280x960 are halved, 1920x1080 divided by 3). Smaller images stay as they are: doubling a
    320x240 frame split fewer objects but lost overlap F (OSD 0.880 -> 0.865)."""
    ratio = float(np.sqrt(shape[0] * shape[1] / reference_pixels))
    return int(round(ratio)) if ratio >= 1.5 else 1


def _resample(image: np.ndarray, shape: tuple[int, int], interpolation: int) -> np.ndarray:
    return cv2.resize(image, (shape[1], shape[0]), interpolation=interpolation)


def _segment(rgb_full, depth_full, K_full, T, params: SegmentationParams, exclude, merge_factory):
    """segment_detailed on a validated frame at the resolution it is segmented at."""
    if exclude is not None:
        depth_full = np.where(exclude, np.float32(0.0), depth_full)
    stride = params.working_stride
    rgb, depth, K, stage = working_stage(rgb_full, depth_full, K_full, T, params)
    maps = learned_maps(rgb, stage, params.boundary)
    crop = fine_crop(stage.objects, stride, depth_full.shape, params.fine) if stride > 1 else None
    if crop is not None:
        K_crop = cropped_intrinsics(K_full, crop)
        cluster = params.fine.cluster_params(params.cluster)
        support = _upsampled_crop(stage.support, crop, stride, depth_full.shape)
        fine = _geometry(depth_full[crop], K_crop, T, params, cluster.step_px, stage.levels, support)
        radii_px = params.fine.candidate_radius_px, params.fine.missing_candidate_radius_px
        _colour(fine, rgb_full[crop], K_crop, T, params, params.fine.table_colour_window_px, radii_px)
        feature_outline = None if maps is None else _upsampled_crop(maps[0], crop, stride, depth_full.shape)
        scorer = merge_scorer(fine, rgb_full[crop], feature_outline, cluster, crop, params, merge_factory)
        labels = np.zeros(depth_full.shape, dtype=np.uint16)
        labels[crop] = _cluster(fine, cluster, params, scorer)
        table = upsample(stage.table, stride, depth_full.shape)
        table[crop] = fine.table
    else:
        radii_px = params.candidate_radius_px, params.missing_candidate_radius_px
        _colour(stage, rgb, K, T, params, params.table_colour_window_px, radii_px)
        grid = (slice(None, None, stride), slice(None, None, stride))
        feature_outline = None if maps is None else maps[0]
        scorer = merge_scorer(stage, rgb, feature_outline, params.cluster, grid, params, merge_factory)
        labels = _cluster(stage, params.cluster, params, scorer)
        table = stage.table
        if stride > 1:
            labels = refine_full_resolution(
                labels, stage.chroma, stage.support, stage.table_chroma, stride, rgb_full, depth_full, K_full, T,
                params.table, params.refine, missing_over_table(depth_full, K_full, T, stage.levels, params.occluders),
            )  # fmt: skip
            table = upsample(table, stride, depth_full.shape)
    if params.fill_closed_missing_px > 0:
        labels = fill_enclosed_missing(labels, depth_full, params.fill_closed_missing_px)
    labels = trim_missing_rim(labels, depth_full, rgb_full, params.missing_rim_close_px, params.rim_window_px)
    if params.fill_enclosed_missing:
        labels = fill_enclosed_missing(labels, depth_full)
    labels = refine_borders(labels, rgb_full, params.border)
    taken = labels[::stride, ::stride] > 0
    occluders = near_occluders(taken, stage.smoothed, rgb, stage.table, K, T, stage.levels, params.occluders)
    if np.any(occluders):
        occluders = upsample(occluders, stride, depth_full.shape)
        add = (labels == 0) & (occluders > 0)
        labels[add] = (occluders[add] + int(labels.max())).astype(np.uint16)
    outline_classifier = shared_outline_classifier(params.outline)
    objectness = None
    if maps is not None and (params.boundary.fill_objects or outline_classifier is not None):
        objectness = upsample_linear(maps[1], stride, depth_full.shape)
    if objectness is not None and params.boundary.fill_objects:
        grown = grow_into_objectness(labels, objectness, params.boundary.fill_threshold, params.boundary.fill_reach_px)
        labels = trim_grown(labels, grown, depth_full, rgb_full, K_full, T, stage.levels, params)
    if objectness is not None and outline_classifier is not None:
        labels = refine_outline(labels, rgb_full, depth_full, objectness, outline_classifier, params.outline)
    if exclude is not None and np.any(labels[exclude]):
        labels = _renumber(np.where(exclude, 0, labels))
    labels = drop_beside_support(labels, stage, stride, params.table)
    labels = absorb_fragments(labels, depth_full, K_full, params.fragments)
    labels = join_overhangs(labels, depth_full, K_full, T, stage.levels, params.overhangs)
    reason = empty_reason(labels, stage.levels, params)
    return SegmentationResult(labels, table, stage.levels, objectness, reason)


def fill_holes(mask: np.ndarray) -> np.ndarray:
    """HxW bool: mask with the background it encloses (not 4-connected to the image border) filled, as
    scipy.ndimage.binary_fill_holes gives it, by one flood fill from outside."""
    padded = np.pad(mask.astype(np.uint8), 1)
    cv2.floodFill(padded, None, (0, 0), 2, flags=4)
    return padded[1:-1, 1:-1] != 2


def fill_enclosed_missing(labels: np.ndarray, depth_m: np.ndarray, close_px: int = 0) -> np.ndarray:
    """Labels with the pixels without depth that the instances enclose (dropout blobs on dark and
    shiny objects), or that their closing by a disc of radius close_px covers, given to the
    nearest instance."""
    box = mask_box(labels, close_px + 1)
    if box is None:
        return labels
    crop = labels[box]
    inside = fill_holes(crop > 0)
    if close_px > 0:
        disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * close_px + 1, 2 * close_px + 1))
        inside |= cv2.morphologyEx((crop > 0).astype(np.uint8), cv2.MORPH_CLOSE, disk) > 0
    holes = inside & (crop == 0) & (depth_m[box] <= 0)
    if not np.any(holes):
        return labels
    rows, cols = np.nonzero(holes)
    iy, ix = nearest_pixel(crop > 0, (rows, cols))
    filled = crop.copy()
    filled[rows, cols] = crop[iy, ix]
    out = labels.copy()
    out[box] = filled
    return out


def trim_missing_rim(labels: np.ndarray, depth_m: np.ndarray, rgb: np.ndarray, close_px: int, window_px: int):
    """Labels without the pixels lacking depth on the outside of the objects that look like the
    background around them.

    A depth sensor loses the returns along depth edges, on both sides of the edge. Pixels without
    depth inside the closing (radius close_px) of an instance's pixels with depth are holes and
    gaps of the object and stay; outside it they stay only where their chromaticity is nearer to
    the instance's mean than to the mean of the unlabelled pixels with depth within window_px."""
    box = mask_box(labels, window_px + close_px)
    if close_px <= 0 or box is None:
        return labels
    out = labels.copy()
    out[box] = _trim_rim(labels[box], depth_m[box], rgb[box], close_px, window_px)
    return out


def _trim_rim(labels, depth_m, rgb, close_px: int, window_px: int):
    missing = (labels > 0) & (depth_m <= 0)
    if not np.any(missing):
        return labels
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * close_px + 1, 2 * close_px + 1))
    solid = (labels > 0) & (depth_m > 0)
    rim = missing & ~(cv2.morphologyEx(solid.astype(np.uint8), cv2.MORPH_CLOSE, disk) > 0)
    if not np.any(rim):
        return labels
    ys, xs = np.nonzero(rim)
    drop = _looks_like_background(labels, labels, depth_m, rgb, ys, xs, window_px)
    out = labels.copy()
    out[ys[drop], xs[drop]] = 0
    return out


def trim_grown(labels, grown, depth_m, rgb, K, T_world_camera, levels, params: SegmentationParams) -> np.ndarray:
    """grown (labels after the object channel's growth), without the added pixels that lack depth
    or lie on a support level (within params.grown_on_support_m) and whose chromaticity is nearer
    the unlabelled pixels with depth around them (params.rim_window_px) than their instance's.

    The object channel cannot tell a projector's shadow on the surface behind an object's edge, or
    the table beside a base, from the object; the colour can. Pixels with depth above the support
    stay: there the geometry backs the network."""
    added = (labels == 0) & (grown > 0)
    ys, xs = np.nonzero(added)
    if not len(ys):
        return grown
    test = depth_m[ys, xs] <= 0
    z = backproject_pixels(depth_m, ys[~test], xs[~test], K, T_world_camera)[:, 2]
    near_support = np.zeros(len(z), dtype=bool)
    for level in levels:
        near_support |= np.abs(z - level.height_m) <= params.grown_on_support_m
    test[~test] = near_support
    ys, xs = ys[test], xs[test]
    if not len(ys):
        return grown
    box = mask_box(grown, params.rim_window_px)
    rows, cols = ys - box[0].start, xs - box[1].start
    drop = _looks_like_background(labels[box], grown[box], depth_m[box], rgb[box], rows, cols, params.rim_window_px)
    out = grown.copy()
    out[ys[drop], xs[drop]] = 0
    return out


def _looks_like_background(solid_labels, labels, depth_m, rgb, ys, xs, window_px: int) -> np.ndarray:
    """bool per pixel (ys, xs) of an instance in labels: its chromaticity is at least as near the mean
    of the unlabelled pixels with depth within window_px as its instance's mean over the pixels with
    depth of solid_labels (never nearer when no such pixel is in the window)."""
    chroma = chromaticity(rgb)
    background = ((labels == 0) & (depth_m > 0)).astype(np.float32)
    ksize = (window_px, window_px)
    count = cv2.boxFilter(background, -1, ksize, normalize=False)
    around = cv2.boxFilter(chroma * background[..., None], -1, ksize, normalize=False)
    means = np.zeros((int(labels.max()) + 1, 3))
    solid_means = instance_colours(np.where(depth_m > 0, solid_labels, 0), chroma)
    means[: len(solid_means)] = solid_means
    pixel = chroma[ys, xs]
    local = around[ys, xs] / np.maximum(count[ys, xs], 1.0)[:, None]
    to_background = np.where(count[ys, xs] > 0, hue_distance(pixel, local), np.inf)
    return hue_distance(pixel, means[labels[ys, xs].astype(np.int64)]) >= to_background


def drop_support_structure(labels, points_world, depth_m, support, levels, params: TableParams) -> np.ndarray:
    """Remove instances that are the side of a higher support level (a shelf's front face).

    Such an instance stands on a lower level and reaches up to a higher level's height at that
    level's footprint; objects on the higher level are measured from it and are kept.
    """
    n = int(labels.max())
    if n == 0 or len(levels) < 2:
        return labels
    z = points_world[..., 2]
    has = (labels > 0) & (depth_m > 0)
    band = band_for_depth(depth_m, params)
    support_of = label_maximum(np.nan_to_num(support, nan=-np.inf), labels, n)[1:]
    drop = np.zeros(n + 1, dtype=bool)
    for level in levels:
        near_top = has & (np.abs(z - level.height_m) <= 2 * band)
        ys, xs = np.nonzero(near_top)
        inside = level.contains_xy(points_world[ys, xs, :2], params.footprint_margin_m)
        reaches = np.bincount(labels[ys[inside], xs[inside]], minlength=n + 1) > 0
        drop[1:] |= reaches[1:] & (np.asarray(support_of) < level.height_m - 0.02)
    if not np.any(drop):
        return labels
    return _renumber(np.where(drop[labels], 0, labels))


def drop_beside_support(labels, stage: _Stage, stride: int, params: TableParams) -> np.ndarray:
    """Labels without the instances that lie mostly outside every support level's footprint (the
    convex hull of the table seen, without margin): a wall rising behind the table's far edge, or
    furniture past it, reaches into the footprint's margin but stands beside the table."""
    sampled = labels[::stride, ::stride][: stage.valid.shape[0], : stage.valid.shape[1]]
    ys, xs = np.nonzero((sampled > 0) & (stage.smoothed > 0))
    if not stage.levels or len(ys) == 0:
        return labels
    xy = stage.points_world[ys, xs, :2]
    over = np.zeros(len(ys), dtype=bool)
    for level in stage.levels:
        over |= level.contains_xy(xy)
    n = int(labels.max()) + 1
    seen = np.bincount(sampled[ys, xs], minlength=n)
    share = np.bincount(sampled[ys, xs], weights=over, minlength=n) / np.maximum(seen, 1)
    beside = (seen > 0) & (share < params.min_share_over_support)
    beside[0] = False
    if not beside.any():
        return labels
    return _renumber(np.where(beside[labels], 0, labels))


def _renumber(labels: np.ndarray) -> np.ndarray:
    used = np.unique(labels)
    remap = np.zeros(int(labels.max()) + 1, dtype=np.uint16)
    remap[used[used > 0]] = np.arange(1, int(np.count_nonzero(used)) + 1, dtype=np.uint16)
    return remap[labels]


def segment(rgb, depth_m, K, T_world_camera, params: SegmentationParams | None = None, exclude=None) -> np.ndarray:
    """RGB-D frame -> instance labels (uint16 HxW): 0 = table / background, k > 0 = object k.

    exclude: optional HxW bool mask of pixels that are never objects (see segment_detailed)."""
    return segment_detailed(rgb, depth_m, K, T_world_camera, params, exclude).labels
