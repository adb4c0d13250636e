"""Surfaces of revolution about the support normal: a test-time completion checked against the view.

Many household objects (cans, bottles, glasses, vases, lamps, bowls) are solids of revolution
standing upright. One view sees about a third of such a surface, and what it sees fixes the rest:
the axis is the common centre of the seen points' horizontal circles, and the radius at each height
is the seen radius there. fit_revolution fits axis and radius profile jointly (linear least squares:
|p|^2 = 2 c . p + b_k per height slice k, r_k^2 = b_k + |c|^2) to the side-wall points facing away
from the axis, drops outliers, and accepts the fit only when the points lie on it (radial residual)
better than on a plane, cover enough of the circle (arc) and the wall is seen from the support up
over most of the height; above the wall, seen points (a lid, a shoulder) continue the profile.
revolution_completion builds the closed solid and uses it only when it does not contradict the view
(seen-empty voxels or other objects inside it). Evaluated with bench_recon against the network alone.
"""

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy import ndimage

from .grid import GridFrame, voxelize_mesh


@dataclass(frozen=True)
class RevolutionSettings:
    """slice_m: height of a profile slice; min_slice_points: points for a slice's circle;
    max_residual_ratio / max_residual_m: largest RMS radial residual, as a share of the median radius
    and in metres (the larger of the two applies); min_arc_deg: smallest angle the seen points span
    around the axis; max_radius_over_extent: largest radius over the seen points' horizontal extent
    (a flat face fits a huge circle); min_points: fewest points for a fit; max_wall_tilt_deg: largest
    angle between a side-wall point's normal and the horizontal; min_curvature_ratio: the wall points'
    RMS distance from their best vertical plane over the circle fit's RMS residual, at least (a flat
    face fits a wide circle as well as a plane); min_height_coverage: share of the slices from the
    support to the top with a wall fit (the lowest within 15 % of the height: nothing is guessed below);
    max_seen_contradiction: largest share of the solid's voxels seen empty or holding another object;
    sections: mesh facets around the axis."""

    slice_m: float = 0.005
    min_slice_points: int = 6
    max_residual_ratio: float = 0.05
    max_residual_m: float = 0.0015
    min_arc_deg: float = 100.0
    max_radius_over_extent: float = 1.0
    min_points: int = 60
    max_wall_tilt_deg: float = 30.0
    min_curvature_ratio: float = 3.0
    min_height_coverage: float = 0.5
    max_seen_contradiction: float = 0.05
    sections: int = 48


@dataclass(frozen=True)
class RevolutionFit:
    """axis_xy: the vertical axis (world x, y, metres); heights_m: slice centres above the support;
    radii_m: radius per slice; top_m: height of the highest seen point above the support;
    rms_residual_m, arc_deg: the fit's quality."""

    axis_xy: np.ndarray
    heights_m: np.ndarray
    radii_m: np.ndarray
    top_m: float
    rms_residual_m: float
    arc_deg: float


def _solve(points: np.ndarray, slices: np.ndarray, n_slices: int) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares centre (2,) and per-slice radius (n_slices,) of circles sharing one centre:
    |p|^2 = 2 c . p + b_k. Each slice's offset b_k is its mean residual, so c solves the 2x2 normal
    equations of the points and targets centred per slice (the same solution as the full system)."""
    xy = points[:, :2]
    target = np.einsum("ij,ij->i", xy, xy)
    counts = np.maximum(np.bincount(slices, minlength=n_slices), 1)
    slice_xy = np.stack([np.bincount(slices, xy[:, i], n_slices) for i in range(2)], axis=1) / counts[:, None]
    slice_target = np.bincount(slices, target, n_slices) / counts
    centred_xy, centred_target = xy - slice_xy[slices], target - slice_target[slices]
    centre = np.linalg.lstsq(2.0 * centred_xy.T @ centred_xy, centred_xy.T @ centred_target, rcond=None)[0]
    offsets = slice_target - 2.0 * slice_xy @ centre
    radii = np.sqrt(np.maximum(offsets + centre @ centre, 0.0))
    return centre, radii


def arc_span_deg(angles: np.ndarray) -> float:
    """Angle (degrees) the directions `angles` (radians) span: 360 minus the largest gap between them."""
    if len(angles) < 2:
        return 0.0
    ordered = np.sort(np.mod(angles, 2 * np.pi))
    gaps = np.diff(np.concatenate([ordered, ordered[:1] + 2 * np.pi]))
    return float(np.degrees(2 * np.pi - gaps.max()))


def fit_revolution(
    points_world: np.ndarray,
    normals_world: np.ndarray,
    support_height_m: float,
    settings: RevolutionSettings = RevolutionSettings(),
) -> RevolutionFit | None:
    """Fit an upright solid of revolution to an object's seen points (N, 3) with their surface normals
    (N, 3, unit, towards the camera); None when they do not lie on one (see RevolutionSettings). Only
    the side wall counts: points whose normal is within max_wall_tilt_deg of horizontal, and (after
    a first fit) facing away from the axis, so a rim, a lid or the inside of a glass does not."""
    points = np.asarray(points_world, dtype=np.float64)
    normals = np.asarray(normals_world, dtype=np.float64)
    top = float(np.percentile(points[:, 2], 99.5)) - support_height_m if len(points) else 0.0
    wall = np.abs(normals[:, 2]) < np.sin(np.radians(settings.max_wall_tilt_deg))
    all_points = points
    points, normals = points[wall], normals[wall]
    if len(points) < settings.min_points:
        return None
    heights = points[:, 2] - support_height_m
    slice_index = np.floor(np.maximum(heights, 0.0) / settings.slice_m).astype(np.int64)
    keep = np.ones(len(points), bool)
    for outlier_round in range(4):  # three rounds of outlier removal, then the final fit
        counts = np.bincount(slice_index[keep], minlength=slice_index.max() + 1)
        keep &= counts[slice_index] >= settings.min_slice_points
        if keep.sum() < settings.min_points:
            return None
        used, dense = np.unique(slice_index[keep], return_inverse=True)
        centre, radii = _solve(points[keep], dense, len(used))
        if outlier_round == 3:
            break
        radius_of_point = np.zeros(slice_index.max() + 1)
        radius_of_point[used] = radii
        offsets = points[:, :2] - centre
        residual = np.linalg.norm(offsets, axis=1) - radius_of_point[slice_index]
        spread = 1.4826 * np.median(np.abs(residual[keep])) + 1e-4
        keep &= (np.abs(residual) <= 3.0 * spread) & (np.einsum("ij,ij->i", offsets, normals[:, :2]) > 0)
    rms = float(np.sqrt(np.mean((np.linalg.norm(points[keep, :2] - centre, axis=1) - radii[dense]) ** 2)))
    offsets = points[keep, :2] - centre
    arc = arc_span_deg(np.arctan2(offsets[:, 1], offsets[:, 0]))
    extent = float(np.max(np.ptp(points[keep, :2], axis=0)))
    wall_xy = points[keep, :2] - points[keep, :2].mean(0)
    plane_rms = float(np.sqrt(np.linalg.eigvalsh(wall_xy.T @ wall_xy / len(wall_xy))[0]))
    median_radius = float(np.median(radii))
    if (
        median_radius <= 0
        or rms > max(settings.max_residual_ratio * median_radius, settings.max_residual_m)
        or arc < settings.min_arc_deg
        or radii.max() > settings.max_radius_over_extent * max(extent, 1e-6)
        or plane_rms < settings.min_curvature_ratio * rms
    ):
        return None
    heights = (used + 0.5) * settings.slice_m
    slices_to_top = max(top / settings.slice_m, 1.0)
    seen_low = heights.min() <= max(2 * settings.slice_m, 0.15 * top)
    if not seen_low or len(used) < settings.min_height_coverage * slices_to_top:
        return None  # the wall is not seen down to the support or over enough of the height
    radii = ndimage.median_filter(radii, size=3, mode="nearest") if len(radii) >= 3 else radii
    heights, radii = _with_cap(all_points, support_height_m, centre, heights, radii, settings.slice_m)
    return RevolutionFit(centre, heights, radii, top, rms, arc)


def _with_cap(points, support_height_m, centre, heights, radii, slice_m) -> tuple[np.ndarray, np.ndarray]:
    """The profile continued above the highest wall slice by the seen points there (a lid, a ball's
    top, a bottle's shoulder): each slice's radius is the 95th percentile of their distances from
    the axis."""
    above = points[:, 2] - support_height_m > heights.max() + slice_m / 2
    if not above.any():
        return heights, radii
    index = np.floor((points[above, 2] - support_height_m) / slice_m).astype(np.int64)
    distance = np.linalg.norm(points[above, :2] - centre, axis=1)
    cap_heights, cap_radii = [], []
    for k in np.unique(index):
        cap_heights.append((k + 0.5) * slice_m)
        cap_radii.append(float(np.percentile(distance[index == k], 95)))
    return np.concatenate([heights, cap_heights]), np.concatenate([radii, cap_radii])


def revolution_mesh(fit: RevolutionFit, support_height_m: float, sections: int = 48) -> trimesh.Trimesh:
    """Closed world-frame solid of the fit: the radius profile from the support up to the top, each
    height's radius interpolated between seen slices and held below the lowest and above the highest."""
    step = max(float(np.min(np.diff(fit.heights_m))) if len(fit.heights_m) > 1 else fit.top_m, 1e-3)
    levels = np.unique(np.concatenate([[0.0], np.arange(step / 2, fit.top_m, step), [fit.top_m]]))
    radii = np.interp(levels, fit.heights_m, fit.radii_m)
    profile = np.concatenate([[[0.0, 0.0]], np.column_stack([radii, levels]), [[0.0, fit.top_m]]])
    mesh = trimesh.creation.revolve(profile, sections=sections)
    mesh.apply_translation([fit.axis_xy[0], fit.axis_xy[1], support_height_m])
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def seen_contradiction(mesh_world: trimesh.Trimesh, frame: GridFrame, grid: np.ndarray) -> float:
    """Share of the mesh's voxels (centres inside it, in the object's grid) that the camera saw empty
    (F3) or saw another object in (F2); 1.0 when it covers no voxel centre."""
    inside = voxelize_mesh(mesh_world, frame)
    if not inside.any():
        return 1.0
    grid = np.asarray(grid)
    return float(((grid[1] > 0) | (grid[2] > 0))[inside].mean())


def revolution_completion(
    points_world,
    normals_world,
    frame: GridFrame,
    grid: np.ndarray,
    settings: RevolutionSettings = RevolutionSettings(),
) -> trimesh.Trimesh | None:
    """The object as an upright solid of revolution (world frame) when its seen points lie on one and the
    solid contradicts the view in at most settings.max_seen_contradiction of its voxels; else None."""
    fit = fit_revolution(points_world, normals_world, frame.table_height_m, settings)
    if fit is None:
        return None
    mesh = revolution_mesh(fit, frame.table_height_m, settings.sections)
    return mesh if seen_contradiction(mesh, frame, grid) <= settings.max_seen_contradiction else None
