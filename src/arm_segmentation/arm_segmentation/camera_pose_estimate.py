"""T_world_camera from one depth image, for cameras without a calibrated camera-to-table transform.

The camera is assumed to look down at a table at most max_camera_height_m below it, rolled at most
max_roll_deg about its optical axis.
The support plane is found by sequential RANSAC (batched hypotheses, vectorized over points) on a
random subsample of the valid depth pixels, each plane refined by weighted least squares on its
inliers. Candidates are planes that can lie under the camera (walls and ceilings cannot, see
plane_problem) and cover a solid region of the image (not the tops of clutter). The plane seen in
most pixels and the planes parallel to it covering at least min_support_area_m2 (or half its area),
one per level min_level_gap_m apart, are the support levels; the one the camera looks at wins (seen
nearest the image centre), so a table over the floor around it and the work table over a second one
behind. Returns beyond max_range_m (far walls, a sensor's outliers at many metres) take no part:
weighted by the area they cover, a few of them would outvote the table.

World frame of the estimate (gravity-aligned, metres):
  z   the plane normal, pointing up (towards the camera); the table top is z = 0;
  x   the optical axis projected on the plane (image up projected when the camera looks within
      1 degree of straight down), so yaw is fixed: the camera looks along +x;
  origin  the foot of the camera on the plane: the camera sits at (0, 0, h), h its height above
      the table (always defined, also when the camera looks up past the table's horizon).
"""

from dataclasses import dataclass

import numpy as np

from arm_core.camera import backproject_image, pixel_coordinates
from arm_core.vectors import vector_length


class CameraPoseError(ValueError):
    """No support plane found; the message says why."""


@dataclass
class CameraPoseEstimate:
    """T_world_camera: 4x4 float64, the optical frame in a gravity-aligned world (z up, table top
    z = 0, camera above it; see the module docstring). inlier_fraction: share of the valid depth
    pixels on the plane. plane_camera: (4,) unit normal n (pointing towards the camera) and d,
    n.p + d = 0 in the camera frame, metres (d is the camera's height above the plane)."""

    T_world_camera: np.ndarray
    inlier_fraction: float
    plane_camera: np.ndarray


@dataclass
class CameraPoseParams:
    max_points: int = 20000  # valid pixels subsampled for the search
    max_range_m: float = 3.5  # returns farther from the camera are ignored (walls, outliers)
    hypotheses: int = 256  # RANSAC planes tried per search ...
    scoring_points: int = 4000  # ... each scored on this many of the points (refinement uses all)
    max_planes: int = 5  # planes extracted one after the other
    inlier_base_m: float = 0.004  # inlier distance at depth 0 ...
    inlier_quadratic_per_m: float = 0.004  # ... plus this times depth^2 (depth noise grows with distance^2)
    min_valid_pixels: int = 1000
    min_inlier_fraction: float = 0.05  # smallest share of valid pixels the largest plane must hold
    min_plane_fraction: float = 0.01  # smallest share of valid pixels any further plane must hold
    min_support_area_m2: float = 0.08  # a parallel plane this large (or half the largest) may be the table ...
    min_dense_share: float = 0.5  # ... when this share of its inliers lie in image cells it dominates
    grid_cells: tuple = (12, 16)  # rows, columns of those image cells
    centre_rank: int = 10  # the support level whose this-many-th inlier lies nearest the image centre wins
    parallel_deg: float = 3.0
    min_level_gap_m: float = 0.1  # parallel support levels lie at least this far apart
    max_look_up_deg: float = 30.0  # the optical axis may rise at most this much above the plane
    max_roll_deg: float = 45.0  # largest camera roll about the optical axis for a plane to be the table ...
    straight_down_deg: float = 20.0  # ... unless the camera looks within this of straight down at it
    min_camera_height_m: float = 0.02
    max_camera_height_m: float = 2.0  # farther planes are walls or a floor far below, not the table
    max_incidence_deg: float = 85.0  # points seen more obliquely than this do not vote for a plane


def _inlier_threshold_m(z_m: np.ndarray, params: CameraPoseParams) -> np.ndarray:
    return params.inlier_base_m + params.inlier_quadratic_per_m * z_m * z_m


def _fit_plane(points: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Weighted least-squares plane (n, d) through points (N, 3), n oriented so that d >= 0."""
    w = weights / weights.sum()
    centroid = w @ points
    centred = points - centroid
    _, _, vt = np.linalg.svd((centred * np.sqrt(w)[:, None]).T @ (centred * np.sqrt(w)[:, None]))
    n = vt[-1]
    d = -float(n @ centroid)
    return np.append(n, d) if d >= 0 else -np.append(n, d)


def _ransac(points: np.ndarray, threshold_m: np.ndarray, rng: np.random.Generator, params: CameraPoseParams):
    """Best plane (4,) by inlier area over params.hypotheses random triples, evaluated together.
    A point counts only where its ray meets the plane less obliquely than max_incidence_deg (a depth
    camera gets no returns beyond): a plane through or near the camera would otherwise hold every
    point near one image line whatever its depth, and outscore a narrow strip of table."""
    triples = points[rng.integers(0, len(points), size=(params.hypotheses, 3))]
    normals = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
    norms = vector_length(normals)
    ok = norms > 1e-9
    normals = normals[ok] / norms[ok, None]
    offsets = -np.einsum("hk,hk->h", normals, triples[ok, 0])
    away = np.abs(offsets) >= params.min_camera_height_m
    if not away.any():
        return None
    normals, offsets = normals[away].astype(np.float32), offsets[away].astype(np.float32)
    points = points.astype(np.float32)  # scoring only: float32 halves the (N, H) work
    distances = np.abs(points @ normals.T + offsets)  # (N, H)
    # |offset| / range is the cosine of the incidence angle of a point on the plane
    seen = np.abs(offsets) >= np.cos(np.radians(params.max_incidence_deg)) * vector_length(points)[:, None]
    # each inlier counts with its depth^2, the area it covers facing the camera: near clutter
    # (many pixels, little area) does not outvote the table
    scores = ((distances < threshold_m[:, None]) & seen).T @ (points[:, 2] ** 2)
    best = int(np.argmax(scores))
    return np.append(normals[best], offsets[best]).astype(np.float64)


def _refine(points: np.ndarray, threshold_m: np.ndarray, plane: np.ndarray, iterations: int = 3):
    """Re-fit on inliers, weighting each point by 1 / threshold^2 (its depth noise); returns (plane, inliers)."""
    inliers = np.abs(points @ plane[:3] + plane[3]) < threshold_m
    for _ in range(iterations):
        if inliers.sum() < 3:
            break
        plane = _fit_plane(points[inliers], 1.0 / threshold_m[inliers] ** 2)
        inliers = np.abs(points @ plane[:3] + plane[3]) < threshold_m
    return plane, inliers


def _plane_area_m2(points: np.ndarray, plane: np.ndarray, fx_fy: float, scale: float) -> float:
    """Area of the plane covered by points (one subsampled pixel stands for `scale` pixels)."""
    ranges = vector_length(points)
    cos = np.abs(points @ plane[:3]) / np.maximum(ranges, 1e-9)
    return float(scale * np.sum(points[:, 2] ** 2 / fx_fy / np.maximum(cos, 0.2)))


def _dense_share(u: np.ndarray, v: np.ndarray, inliers: np.ndarray, shape, params: CameraPoseParams) -> float:
    """Share of a plane's inliers lying in image cells where they are the majority of the points. A
    real support covers a solid region; a plane grazing the tops and sides of clutter has its inliers
    scattered among other surfaces."""
    rows, cols = params.grid_cells
    col = np.clip((u * cols / shape[1]).astype(np.int64), 0, cols - 1)
    row = np.clip((v * rows / shape[0]).astype(np.int64), 0, rows - 1)
    cell = row * cols + col
    totals = np.bincount(cell, minlength=rows * cols)
    on_plane = np.bincount(cell[inliers], minlength=rows * cols)
    dominated = on_plane >= 0.5 * np.maximum(totals, 1)
    return float(on_plane[dominated].sum() / max(on_plane.sum(), 1))


def valid_points(
    depth_m: np.ndarray, K: np.ndarray, max_points: int, rng: np.random.Generator, max_range_m: float = np.inf
) -> tuple[np.ndarray, int]:
    """(points, n): camera-frame points (N, 3) of a random subsample of the n valid depth pixels
    whose return lies within max_range_m of the camera."""
    depth_m = np.asarray(depth_m, dtype=np.float32)
    valid = (np.isfinite(depth_m) & (depth_m > 0)).ravel()
    points = backproject_image(np.where(valid.reshape(depth_m.shape), depth_m, 0.0), K).reshape(-1, 3)[valid]
    points = points[vector_length(points) <= max_range_m]
    n_valid = len(points)
    if len(points) > max_points:
        points = points[rng.choice(len(points), max_points, replace=False)]
    return points.astype(np.float64), n_valid


def plane_problem(plane: np.ndarray, params: CameraPoseParams) -> str:
    """Why a plane (n towards the camera, d) cannot be the support under the camera; '' if it can.
    Taken as the table, the plane's normal is world-up seen from the camera: its direction in the
    image gives the camera's roll (0 when up is image-up), its depth component the pitch."""
    n, d = plane[:3], plane[3]
    if d < params.min_camera_height_m:
        return f"plane passes {d * 100:.1f} cm from the camera (behind or through it)"
    if d > params.max_camera_height_m:
        return f"plane lies {d:.2f} m from the camera, farther than {params.max_camera_height_m} m (a wall?)"
    if np.hypot(n[0], n[1]) > np.sin(np.radians(params.straight_down_deg)):  # else roll is undefined
        roll = np.degrees(np.arctan2(n[0], -n[1]))
        if abs(roll) > 135.0:
            return "plane faces down the image (a ceiling or a front face above the camera, or an upside-down camera)"
        if abs(roll) > params.max_roll_deg:
            return f"plane stands upright in the image (a wall?): the camera would be rolled {roll:.0f} deg"
    if n[2] > np.sin(np.radians(params.max_look_up_deg)):
        rise = np.degrees(np.arcsin(np.clip(n[2], -1, 1)))
        return f"camera not looking down: its optical axis rises {rise:.0f} deg above the plane"
    return ""


def support_planes(points: np.ndarray, params: CameraPoseParams, rng: np.random.Generator) -> list:
    """Sequential RANSAC: up to max_planes (plane, inlier mask over points) pairs, in the order found."""
    threshold_m = _inlier_threshold_m(points[:, 2], params)
    remaining = np.ones(len(points), bool)
    min_inliers = max(3, int(params.min_plane_fraction * len(points)))
    planes = []
    for _ in range(params.max_planes):
        index = np.flatnonzero(remaining)
        if len(index) < min_inliers:
            break
        sample = index if len(index) <= params.scoring_points else rng.choice(index, params.scoring_points, False)
        plane = _ransac(points[sample], threshold_m[sample], rng, params)
        if plane is None:
            break
        plane, inliers = _refine(points[index], threshold_m[index], plane)
        if inliers.sum() < min_inliers:
            break
        # inliers over all points (a plane may take back points of an earlier, crossing plane)
        all_inliers = np.abs(points @ plane[:3] + plane[3]) < threshold_m
        planes.append((plane, all_inliers))
        # leave out the plane's noisy fringe too, or it comes back as a sliver plane next to it
        remaining &= np.abs(points @ plane[:3] + plane[3]) >= 2.0 * threshold_m
    return planes


def world_from_plane(plane: np.ndarray) -> np.ndarray:
    """T_world_camera for a support plane (n towards the camera, d) in the camera frame (module docstring)."""
    n, d = plane[:3] / np.linalg.norm(plane[:3]), float(plane[3])
    axis = np.array([0.0, 0.0, 1.0])
    if np.linalg.norm(axis - (axis @ n) * n) < np.sin(np.radians(1.0)):
        axis = np.array([0.0, -1.0, 0.0])  # looking straight down: image up gives the yaw
    x = axis - (axis @ n) * n
    x /= np.linalg.norm(x)
    R_world_camera = np.stack([x, np.cross(n, x), n])
    T = np.eye(4)
    T[:3, :3] = R_world_camera
    T[:3, 3] = (0.0, 0.0, d)
    return T


def estimate_camera_pose(
    depth_m: np.ndarray, K: np.ndarray, *, rng_seed: int = 0, params: CameraPoseParams | None = None
) -> CameraPoseEstimate:
    """The camera's pose over the dominant support plane of a depth image (metres, 0 = no return)
    with intrinsics K. Raises CameraPoseError with the reason when there is no usable plane."""
    params = params or CameraPoseParams()
    depth_m = np.asarray(depth_m)
    K = np.asarray(K, dtype=np.float64)
    if depth_m.ndim != 2 or K.shape != (3, 3):
        raise CameraPoseError(f"expected an HxW depth image and a 3x3 K, got {depth_m.shape} and {K.shape}")
    rng = np.random.default_rng(rng_seed)
    points, n_valid = valid_points(depth_m, K, params.max_points, rng, params.max_range_m)
    if n_valid < params.min_valid_pixels:
        raise CameraPoseError(
            f"too few valid depth pixels within {params.max_range_m} m: {n_valid} < {params.min_valid_pixels}"
        )
    planes = support_planes(points, params, rng)
    if not planes or max(inliers.mean() for _, inliers in planes) < params.min_inlier_fraction:
        raise CameraPoseError(f"no plane holds {params.min_inlier_fraction:.0%} of the {n_valid} valid depth pixels")
    u, v = pixel_coordinates(points, K)
    problems = [plane_problem(plane, params) for plane, _ in planes]
    usable = [
        (plane, inliers)
        for (plane, inliers), problem in zip(planes, problems, strict=True)
        if not problem and _dense_share(u, v, inliers, depth_m.shape, params) >= params.min_dense_share
    ]
    if not usable:
        raise CameraPoseError(next((p for p in problems if p), "no plane covers a solid region of the image"))
    scale = n_valid / len(points)
    fx_fy = K[0, 0] * K[1, 1]
    areas = [_plane_area_m2(points[inliers], plane, fx_fy, scale) for plane, inliers in usable]
    # seen in most pixels, not largest in m^2: a far strip of wall or floor, or a sensor's far
    # outliers, can cover more square metres than the table in front of the camera
    largest = int(np.argmax([inliers.sum() for _, inliers in usable]))
    cos_parallel = np.cos(np.radians(params.parallel_deg))
    min_area = min(params.min_support_area_m2, 0.5 * areas[largest])
    largest_plane = usable[largest][0]
    # support levels parallel to the largest plane, one per height: of planes closer than
    # min_level_gap_m to each other (a sliver along the table's noisy fringe) the larger one stands
    supports = []
    for i in sorted(range(len(usable)), key=lambda i: (i != largest, -areas[i])):
        plane = usable[i][0]
        if i != largest and not (
            plane[:3] @ largest_plane[:3] > cos_parallel
            and all(abs(plane[3] - usable[j][0][3]) >= params.min_level_gap_m for j in supports)
            and areas[i] >= min_area
        ):
            continue
        supports.append(i)
    # the level the camera looks at: the one seen nearest the image centre (its 10th nearest
    # inlier, robust to stray points), so a table over the floor around it and the work table over
    # a second one behind; the objects on a table hide at most part of it around the centre
    h, w = depth_m.shape
    from_centre_px = np.hypot(u - 0.5 * w, v - 0.5 * h)

    def centre_distance_px(i: int) -> float:
        near = np.sort(from_centre_px[usable[i][1]])
        return float(near[min(len(near) - 1, params.centre_rank)])

    plane, inliers = usable[min(supports, key=lambda i: (centre_distance_px(i), usable[i][0][3]))]
    return CameraPoseEstimate(world_from_plane(plane), float(inliers.mean()), plane.copy())


def plane_inlier_fraction(
    depth_m: np.ndarray,
    K: np.ndarray,
    plane_camera: np.ndarray,
    *,
    rng_seed: int = 0,
    params: CameraPoseParams | None = None,
) -> float:
    """Share of a subsample of the valid depth pixels within the inlier distance of a known plane:
    a cheap check that an earlier estimate still holds for a new frame."""
    params = params or CameraPoseParams()
    points, _ = valid_points(depth_m, K, params.max_points // 4, np.random.default_rng(rng_seed), params.max_range_m)
    if len(points) == 0:
        return 0.0
    distances = np.abs(points @ plane_camera[:3] + plane_camera[3])
    return float(np.mean(distances < _inlier_threshold_m(points[:, 2], params)))
