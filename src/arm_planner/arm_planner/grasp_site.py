"""Where to grasp: a point and a closing axis with the target's material between the open fingers.

The grasp reward's default site is over the centre of mass, closing across the narrowest extent. On
a ring, a torus, a U or an L the centre of mass can lie over empty space (the fingers close on
nothing), or the fingers come down on the object itself. Then the site moves to the nearest place,
over a grid of points and axes on the target's footprint, where both open fingers come down clear
of the target, its material lies squarely between them, and the fingers clear the other objects.
The same search tells a target no parallel gripper can pick up. The target is its convex parts as
half-spaces (n . x + d <= 0 inside, world frame, metres), sampled once on a voxel grid.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from arm_planner.finger_clearance import OpenFingers, clearance_m, finger_points


@dataclass(frozen=True)
class GraspSite:
    point_world: np.ndarray  # the TCP's grasp point, m
    axis_xy: np.ndarray  # unit horizontal closing axis, [3] with z 0
    moved: bool  # False: the default site was kept
    holds: bool = True  # False: the default site does not hold the target and no other site does


@dataclass(frozen=True)
class GraspTarget:
    """What the search needs of the target (world frame, metres): its centre of mass, its convex parts
    (half-spaces) and their vertices, the table height, the TCP's depth band below the target's top,
    and the other objects' convex parts (None: not checked)."""

    com_world: np.ndarray
    vertices_world: np.ndarray
    part_halfspaces: list
    table_height_m: float
    min_depth_m: float
    max_depth_m: float
    obstacle_halfspaces: list | None = None


@dataclass(frozen=True)
class Occupancy:
    """Which voxels (edge voxel_m, metres) of a box starting at origin_world lie inside the target."""

    origin_world: np.ndarray
    voxel_m: float
    filled: np.ndarray  # bool [nx, ny, nz]

    @classmethod
    def from_parts(cls, part_halfspaces: list[np.ndarray], lo: np.ndarray, hi: np.ndarray, voxel_m: float):
        counts = np.maximum(np.ceil((np.asarray(hi) - lo) / voxel_m).astype(int), 1)
        axes = [lo[k] + voxel_m * (np.arange(counts[k]) + 0.5) for k in range(3)]
        centres = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        filled = inside_parts(centres, part_halfspaces).reshape(counts)
        return cls(np.asarray(lo, dtype=np.float64), float(voxel_m), filled)

    def columns(self, points_xy: np.ndarray) -> np.ndarray:
        """bool [..., Z]: the voxel column under each point [..., 2]; empty outside the box."""
        index = np.floor((points_xy - self.origin_world[:2]) / self.voxel_m).astype(int)
        valid = np.all((index >= 0) & (index < np.array(self.filled.shape[:2])), axis=-1)
        index = np.where(valid[..., None], index, 0)
        return self.filled[index[..., 0], index[..., 1]] & valid[..., None]


def inside_parts(points_world: np.ndarray, part_halfspaces: list[np.ndarray]) -> np.ndarray:
    """bool [N]: the point lies inside at least one convex part."""
    points_world = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
    inside = np.zeros(len(points_world), dtype=bool)
    for planes in part_halfspaces:  # a few parts; each test is vectorised over the points
        inside |= (points_world @ planes[:, :3].T + planes[:, 3]).max(axis=1) <= 0.0
    return inside


def span_offsets(fingers: OpenFingers, samples_along: int = 17, samples_across: int = 3) -> np.ndarray:
    """[K, 2] (along the closing axis, across it) offsets of points between the open fingers, m;
    along-major (K = samples_along x samples_across)."""
    half = 0.5 * fingers.gap_m - 0.25 * fingers.thickness_m
    along = np.linspace(-half, half, samples_along)
    across = np.linspace(-0.4, 0.4, samples_across) * fingers.width_m
    a, b = np.meshgrid(along, across, indexing="ij")
    return np.column_stack([a.reshape(-1), b.reshape(-1)])


def _rotate(offsets: np.ndarray, axes_xy: np.ndarray) -> np.ndarray:
    """[A, K, 2] world xy offsets of (along, across) offsets for each unit axis [A, 2]."""
    across = np.stack([-axes_xy[:, 1], axes_xy[:, 0]], axis=1)
    return offsets[None, :, :1] * axes_xy[:, None, :] + offsets[None, :, 1:] * across[:, None, :]


def default_site_holds(
    point_world: np.ndarray,
    axis_xy: np.ndarray,
    fingers: OpenFingers,
    part_halfspaces: list[np.ndarray],
    finger_depth_m: float = 0.005,
) -> bool:
    """Target material lies between the open fingers of a TCP at point_world closing along axis_xy
    (from the fingertips to 1 cm above the TCP), and neither finger comes down more than
    finger_depth_m into the target."""
    axis = np.asarray(axis_xy, dtype=np.float64)[:2]
    axis = axis / (np.linalg.norm(axis) + 1e-12)
    offsets = _rotate(span_offsets(fingers), axis[None])[0]
    heights = np.linspace(point_world[2] - fingers.tcp_above_tip_m, point_world[2] + 0.01, 4)
    points = np.concatenate([np.column_stack([point_world[:2] + offsets, np.full(len(offsets), z)]) for z in heights])
    if not inside_parts(points, part_halfspaces).any():
        return False
    return clearance_m(finger_points(point_world, axis, fingers), part_halfspaces) > -finger_depth_m


def find_grasp_site(
    default_point_world: np.ndarray, default_axis_xy: np.ndarray, target: GraspTarget, fingers: OpenFingers
) -> GraspSite:
    """The default site when it holds (default_site_holds), else the nearest site that does
    (search_grasp_site); the default, marked as not holding, when none does."""
    default = GraspSite(np.asarray(default_point_world, dtype=np.float64), np.asarray(default_axis_xy), False)
    if not fingers.known or not target.part_halfspaces or len(target.vertices_world) == 0:
        return default
    if default_site_holds(default.point_world, default.axis_xy, fingers, target.part_halfspaces):
        return default
    return search_grasp_site(target, fingers) or dataclasses.replace(default, holds=False)


def search_grasp_site(
    target: GraspTarget,
    fingers: OpenFingers,
    spacing_m: float = 0.01,
    axes: int = 12,
    voxel_m: float = 0.004,
    above_table_m: float = 0.015,
    centring_weight: float = 2.0,
) -> GraspSite | None:
    """Of a grid of points (spacing_m) and closing axes over the target's footprint, the site nearest
    the centre of mass (horizontally, plus centring_weight x the material's offset from the middle of
    the fingers) whose open fingers come down clear of the target with its material squarely between
    them, preferring one whose fingers clear the other objects; None when none qualifies (the target
    is wider than the gap wherever its material lies between the fingers). A site's TCP height is the
    centre of mass's, kept within the target's depth band below its top under the fingers and
    above_table_m above the table."""
    com_world, vertices_world, part_halfspaces = target.com_world, target.vertices_world, target.part_halfspaces
    if not fingers.known or not part_halfspaces or len(vertices_world) == 0:
        return None
    lo, hi = vertices_world.min(axis=0) - voxel_m, vertices_world.max(axis=0) + voxel_m
    occupancy = Occupancy.from_parts(part_halfspaces, lo, hi, voxel_m)
    levels = occupancy.origin_world[2] + voxel_m * (np.arange(occupancy.filled.shape[2]) + 0.5)  # [Z]

    gx, gy = np.meshgrid(np.arange(lo[0], hi[0], spacing_m), np.arange(lo[1], hi[1], spacing_m), indexing="ij")
    points_xy = np.column_stack([gx.reshape(-1), gy.reshape(-1)])  # [P, 2]
    angles = np.pi * np.arange(axes) / axes
    axes_xy = np.column_stack([np.cos(angles), np.sin(angles)])  # [A, 2]

    # Between the fingers: the target's top there, and whether it has material from the fingertips
    # up to 1 cm above the TCP (the TCP at the centre of mass's height within the depth band).
    offsets = span_offsets(fingers)
    along = offsets[:, 0].reshape(-1, 3)[:, 0]
    between = occupancy.columns(points_xy[:, None, None] + _rotate(offsets, axes_xy)[None])  # [P, A, K, Z]
    has_level = between.any(axis=2)  # [P, A, Z]
    has_material = has_level.any(axis=-1)
    top_index = np.argmax(np.where(has_level, np.arange(len(levels)), -1), axis=-1)
    top = np.where(has_material, levels[top_index] + 0.5 * voxel_m, -np.inf)
    z = np.clip(com_world[2], top - target.max_depth_m, top - target.min_depth_m)
    z = np.maximum(z, target.table_height_m + above_table_m)
    tip = z - fingers.tcp_above_tip_m
    band = (levels >= tip[..., None] - 0.5 * voxel_m) & (levels <= z[..., None] + 0.01)  # [P, A, Z]
    held = (between & band[:, :, None, :]).any(axis=-1)
    held = held.reshape(*band.shape[:2], len(along), -1)  # [P, A, along, across]
    # Antipodal: each row across the finger width holds material, and the material's ends along the
    # axis line up across the rows (faces square to the fingers, not a corner or a slanted side).
    rows = held.any(axis=2)  # [P, A, across]
    index = np.arange(len(along))[:, None]
    first = np.where(held, index, len(along)).min(axis=2)
    last = np.where(held, index, -1).max(axis=2)
    square = (np.ptp(first, axis=-1) <= 1) & (np.ptp(last, axis=-1) <= 1)
    ok = has_material & rows.all(axis=-1) & square
    centring = np.abs(0.5 * (along[np.minimum(first, len(along) - 1)] + along[np.maximum(last, 0)]).mean(axis=-1))

    # Both open fingers clear of the target, from their tips up to the palm.
    footprint = finger_points(np.zeros(3), np.array([1.0, 0.0]), fingers)[:, :2]
    footprint = np.unique(np.round(footprint, 6), axis=0)
    fingers_at = occupancy.columns(points_xy[:, None, None] + _rotate(footprint, axes_xy)[None]).any(axis=2)
    finger_range = (levels >= tip[..., None] - 0.5 * voxel_m) & (levels <= tip[..., None] + fingers.length_m)
    ok &= ~(fingers_at & finger_range).any(axis=-1)
    if not ok.any():
        return None

    p_index, a_index = np.nonzero(ok)
    score = np.linalg.norm(points_xy[p_index] - com_world[:2], axis=1) + centring_weight * centring[p_index, a_index]
    order = np.argsort(score, kind="stable")
    best = None
    for i in order[:64]:
        point = np.array([*points_xy[p_index[i]], z[p_index[i], a_index[i]]])
        site = GraspSite(point, np.append(axes_xy[a_index[i]], 0.0), True)
        best = best or site
        if not target.obstacle_halfspaces:
            return site
        if clearance_m(finger_points(point, site.axis_xy, fingers), target.obstacle_halfspaces) >= 0:
            return site
    return best
