"""Upright cuboids on their support or on the object under them: a test-time completion checked
against the view, as revolution.py's for solids of revolution.

Boxes (cereal, crackers, tea, shoe boxes) are the other common household shape, and a box completed
as a rounded blob rocks, rolls and slides off the box it is stacked on. One view from above a table
sees a box's top and one or two of its side walls, and they fix the rest: the side walls' horizontal
normals agree modulo 90 degrees (the box's yaw), each seen wall places its side (the median of its
points along that axis), a hidden side lies at the farthest seen point (the top face reaches it) and
the top at the highest seen points. The bottom is the support where the walls are seen down to it or
hidden below (by an object in front); where they end above it on another object's reconstruction
(a box on a box), the cuboid rests there. cuboid_completion accepts the cuboid only when the seen
points lie on its faces and it covers few voxels seen empty or holding another object.
"""

from dataclasses import dataclass

import numpy as np
import trimesh

from .grid import GridFrame, voxelize_mesh
from .revolution import seen_contradiction

REST_PROBES = 8  # rays down each side of the footprint that look for an object under a cuboid


@dataclass(frozen=True)
class CuboidSettings:
    """max_wall_tilt_deg: largest angle between a side-wall point's normal and the horizontal;
    min_wall_points: fewest side-wall points; max_slanted_share: the largest share of points whose
    normal is neither a wall's nor a top's (a lying can's, a ball's); min_yaw_coherence: least length
    of the mean of the wall normals' directions taken modulo 90 degrees (1: every normal along one of
    the four sides); min_face_points: fewest points that place a side from its seen face, which must
    lie within face_at_side_m of the farthest seen point that way (else a fold or an edge: the side is
    at that point, which needs min_top_points points facing up; they place the top too); min_side_m:
    the least width, depth and height; surface_tolerance_m / min_surface_share: the share of the seen
    points within this distance of the cuboid's surface, at least; seen_low_share / seen_low_m: walls
    seen down to this share of the height (or this far) above the support reach it; rest_below_m /
    min_rest_share: walls ending higher rest on another object whose reconstruction's surface lies
    between this far below their end and surface_tolerance_m above it under at least this share of the
    footprint (rest_height_m); min_seen_past_share / max_hidden_past_share: a hidden side needs
    the view past it (hidden_sides_in_view); max_seen_contradiction: as revolution.RevolutionSettings'."""

    max_wall_tilt_deg: float = 30.0
    min_wall_points: int = 60
    max_slanted_share: float = 0.2
    min_yaw_coherence: float = 0.7
    min_face_points: int = 30
    face_at_side_m: float = 0.01
    min_top_points: int = 30
    min_side_m: float = 0.01
    surface_tolerance_m: float = 0.005
    min_surface_share: float = 0.85
    seen_low_share: float = 0.15
    seen_low_m: float = 0.01
    rest_below_m: float = 0.02
    min_rest_share: float = 0.25
    min_seen_past_share: float = 0.25
    max_hidden_past_share: float = 0.5
    max_seen_contradiction: float = 0.05


@dataclass(frozen=True)
class CuboidFit:
    """yaw_rad: the box's first side axis from world x about the vertical; lo_m / hi_m: its extent
    along its two side axes (metres, in the yawed frame); bottom_m / top_m: world heights; walls_end_m:
    the world height where the seen side walls end at the bottom."""

    yaw_rad: float
    lo_m: np.ndarray
    hi_m: np.ndarray
    bottom_m: float
    top_m: float
    walls_end_m: float
    hidden_sides: tuple = ()  # (axis, -1 low / +1 high) of the sides placed by the farthest seen point

    @property
    def axes(self) -> np.ndarray:
        """(2, 2) rows: the box's side axes in world xy."""
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        return np.array([[c, s], [-s, c]])

    def with_bottom(self, bottom_m: float) -> "CuboidFit":
        return CuboidFit(
            self.yaw_rad, self.lo_m, self.hi_m, float(bottom_m), self.top_m, self.walls_end_m, self.hidden_sides
        )


def fit_cuboid(
    points_world: np.ndarray,
    normals_world: np.ndarray,
    support_height_m: float,
    settings: CuboidSettings = CuboidSettings(),
) -> CuboidFit | None:
    """An upright cuboid through an object's seen points (N, 3) with their unit normals (N, 3, towards
    the camera), standing on the support; None when the points do not lie on one (CuboidSettings)."""
    points = np.asarray(points_world, dtype=np.float64)
    normals = np.asarray(normals_world, dtype=np.float64)
    s = settings
    wall = (np.linalg.norm(normals, axis=1) > 0.5) & (np.abs(normals[:, 2]) < np.sin(np.radians(s.max_wall_tilt_deg)))
    facing_up = normals[:, 2] > np.cos(np.radians(s.max_wall_tilt_deg))
    if wall.sum() < s.min_wall_points or 1.0 - (wall.sum() + facing_up.sum()) / len(points) > s.max_slanted_share:
        return None  # a box's faces are walls and a top: a share of slanted normals is a rounded shape
    mean_direction = np.mean(np.exp(4j * np.arctan2(normals[wall, 1], normals[wall, 0])))
    if abs(mean_direction) < s.min_yaw_coherence:
        return None
    yaw = float(np.angle(mean_direction) / 4.0)
    fit = CuboidFit(yaw, np.zeros(2), np.zeros(2), support_height_m, 0.0, 0.0)
    side_uv = points[:, :2] @ fit.axes.T
    wall_uv, wall_normal_uv = side_uv[wall], normals[wall, :2] @ fit.axes.T
    along = np.argmax(np.abs(wall_normal_uv), axis=1)
    facing = np.sign(wall_normal_uv[np.arange(len(along)), along])
    top_points = int(facing_up.sum())
    lo, hi = np.zeros(2), np.zeros(2)
    on_face = np.zeros(len(wall_uv), bool)  # wall points on a seen face's plane (not a neighbour's)
    hidden = []
    for axis in range(2):
        for sign, bound, percentile in ((-1.0, lo, 1.0), (1.0, hi, 99.0)):
            in_face = (along == axis) & (facing == sign)
            face = wall_uv[in_face, axis]
            farthest = float(np.percentile(side_uv[:, axis], percentile))
            if len(face) >= s.min_face_points and abs(np.median(face) - farthest) <= s.face_at_side_m:
                bound[axis] = float(np.median(face))
                on_face |= in_face & (np.abs(wall_uv[:, axis] - bound[axis]) <= s.surface_tolerance_m)
            elif top_points >= s.min_top_points:
                bound[axis] = farthest
                hidden.append((axis, int(sign)))
            else:
                return None  # a hidden side and no top to reach it
    top = float(np.percentile(points[:, 2], 99.5))
    if top_points >= s.min_top_points:  # the top face, not the highest stray point
        up_z = points[facing_up, 2]
        top = float(np.median(up_z[up_z >= np.percentile(up_z, 90) - s.face_at_side_m]))
    walls_end = float(np.percentile(points[wall][on_face if on_face.any() else slice(None), 2], 1.0))
    if np.any(hi - lo < s.min_side_m) or top - support_height_m < s.min_side_m:
        return None
    fit = CuboidFit(yaw, lo, hi, support_height_m, top, walls_end, tuple(hidden))
    if surface_share(fit, points, s.surface_tolerance_m) < s.min_surface_share:
        return None
    return fit


def surface_share(fit: CuboidFit, points_world: np.ndarray, tolerance_m: float) -> float:
    """Share of the points (N, 3) within tolerance_m of the cuboid's surface (inside or out); seen
    points lie on faces, so a shape that is not this cuboid leaves many off it."""
    local = np.column_stack([points_world[:, :2] @ fit.axes.T, points_world[:, 2]])
    lo = np.array([*fit.lo_m, fit.bottom_m])
    hi = np.array([*fit.hi_m, fit.top_m])
    outside = np.linalg.norm(np.maximum(np.maximum(lo - local, local - hi), 0.0), axis=1)
    inside = np.minimum(local - lo, hi - local).min(axis=1)
    distance = np.where(outside > 0, outside, np.maximum(inside, 0.0))
    return float(np.mean(distance <= tolerance_m)) if len(distance) else 0.0


def cuboid_mesh(fit: CuboidFit) -> trimesh.Trimesh:
    """The closed world-frame cuboid of the fit."""
    centre_uv = (fit.lo_m + fit.hi_m) / 2
    transform = np.eye(4)
    transform[:2, :2] = fit.axes.T
    transform[:2, 3] = fit.axes.T @ centre_uv
    transform[2, 3] = (fit.bottom_m + fit.top_m) / 2
    extents = [*(fit.hi_m - fit.lo_m), fit.top_m - fit.bottom_m]
    return trimesh.creation.box(extents=extents, transform=transform)


def rest_height_m(fit: CuboidFit, other_meshes, settings: CuboidSettings) -> float | None:
    """The height (world, m) of the other objects' reconstructions (world-frame meshes) under the
    cuboid, where their surface lies between rest_below_m under the end of its seen walls and
    surface_tolerance_m over it, under at least min_rest_share of its footprint (a box stacked on a
    box; walls seen lower than that surface pass in front of it): the 90th percentile of their
    surface there, so that it rests on their high points; None when they do not."""
    side = (np.arange(REST_PROBES) + 0.5) / REST_PROBES
    u, v = np.meshgrid(*(fit.lo_m[:, None] + (fit.hi_m - fit.lo_m)[:, None] * side))
    xy = np.column_stack([u.ravel(), v.ravel()]) @ fit.axes
    low, high = xy.min(axis=0), xy.max(axis=0)
    meshes = [
        m for m in other_meshes if len(m.faces) and np.all(m.bounds[0, :2] <= high) and np.all(m.bounds[1, :2] >= low)
    ]  # those over the footprint
    if not meshes:
        return None
    start_m = fit.top_m - settings.min_side_m  # under its own top: what lies higher is on it, not under it
    origins = np.column_stack([xy, np.full(len(xy), start_m)])
    directions = np.tile([0.0, 0.0, -1.0], (len(xy), 1))
    surface = np.full(len(xy), -np.inf)
    for mesh in meshes:
        hits, rays, _ = mesh.ray.intersects_location(origins, directions, multiple_hits=False)
        if len(rays):
            np.maximum.at(surface, rays, np.asarray(hits).reshape(-1, 3)[:, 2])
    # the walls end on it: it reaches up to near their end, and they are not seen below its top
    under = (surface >= fit.walls_end_m - settings.rest_below_m) & (
        surface <= fit.walls_end_m + settings.surface_tolerance_m
    )
    if under.mean() < settings.min_rest_share:
        return None
    return float(np.percentile(surface[under], 90))


def hidden_sides_in_view(
    fit: CuboidFit, frame: GridFrame, grid: np.ndarray, hidden_by_others, settings: CuboidSettings
) -> bool:
    """Whether the view bounds each hidden side. Of the voxel centres along its top edge, the two
    beyond the one at it (which may hold its points): at least min_seen_past_share were seen empty
    (the camera saw the box end along part of the edge, beside an object standing on it, say), or at
    most max_hidden_past_share are hidden by another object or the image's edge (hidden_by_others:
    (N, 3) world points -> (N,) bool; a sensor's shadow, no depth beside an edge, hides nothing).
    Else the box may go on there, and the network's completion is kept."""
    voxel = frame.voxel_size_m
    seen_empty = np.asarray(grid)[2] > 0
    for axis, sign in fit.hidden_sides:
        lo, hi = fit.lo_m.copy(), fit.hi_m.copy()
        if sign > 0:
            lo[axis], hi[axis] = fit.hi_m[axis] + voxel, fit.hi_m[axis] + 3 * voxel
        else:
            lo[axis], hi[axis] = fit.lo_m[axis] - 3 * voxel, fit.lo_m[axis] - voxel
        past = CuboidFit(fit.yaw_rad, lo, hi, fit.top_m - 2 * voxel, fit.top_m, fit.top_m)
        inside = voxelize_mesh(cuboid_mesh(past), frame)
        if not inside.any() or float(seen_empty[inside].mean()) >= settings.min_seen_past_share:
            continue
        centres = frame.voxel_to_world(np.argwhere(inside) + 0.5)
        if float(np.mean(hidden_by_others(centres))) > settings.max_hidden_past_share:
            return False
    return True


def cuboid_completion(
    points_world,
    normals_world,
    frame: GridFrame,
    grid: np.ndarray,
    other_meshes=(),
    hidden_by_others=None,
    settings: CuboidSettings = CuboidSettings(),
) -> trimesh.Trimesh | None:
    """The object as an upright cuboid (world frame) when its seen points lie on one and the cuboid
    contradicts the view in at most settings.max_seen_contradiction of its voxels; else None.
    other_meshes: the frame's other objects' reconstructions (world frame), which a box may rest on;
    hidden_by_others: as hidden_sides_in_view's (None: nothing hides what lies past the box)."""
    support = frame.table_height_m
    fit = fit_cuboid(points_world, normals_world, support, settings)
    if fit is None:
        return None
    height = fit.top_m - support
    seen_low = fit.walls_end_m - support <= max(settings.seen_low_m, settings.seen_low_share * height)
    rest_m = None if seen_low else rest_height_m(fit, other_meshes, settings)
    if rest_m is not None:
        fit = fit.with_bottom(rest_m)
    if hidden_by_others is not None and not hidden_sides_in_view(fit, frame, grid, hidden_by_others, settings):
        return None
    mesh = cuboid_mesh(fit)
    return mesh if seen_contradiction(mesh, frame, grid) <= settings.max_seen_contradiction else None
