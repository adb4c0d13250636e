"""Where the open fingers land around a grasp point, and a closing axis that keeps them off the
other objects.

The hand comes down vertically over the grasp point with its fingers open; each finger is a box
`thickness_m` along the closing axis and `width_m` across it, from its tip up `length_m` to the palm.
A finger that lands on a neighbour holds the hand above the grasp point (the fingers never reach
the target), so the closing axis is turned, as little as it takes, to where both fingers fit.
Obstacles are convex parts given as half-spaces (n . x + d <= 0 inside, world frame, metres).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh


@dataclass(frozen=True)
class OpenFingers:
    """The open fingers: inner gap, thickness along the closing axis, width across it, length from
    tip to palm, and the TCP's height above the tips; and the palm they hang from, its length along
    the closing axis and width across it (0: unknown, not checked) (metres)."""

    gap_m: float
    thickness_m: float
    width_m: float
    length_m: float
    tcp_above_tip_m: float
    palm_length_m: float = 0.0
    palm_width_m: float = 0.0

    @property
    def known(self) -> bool:
        return min(self.gap_m, self.thickness_m, self.width_m, self.length_m) > 0

    @property
    def palm_known(self) -> bool:
        return self.known and min(self.palm_length_m, self.palm_width_m) > 0


def halfspaces(part: trimesh.Trimesh) -> np.ndarray:
    """[F, 4] planes (unit normal, offset) of a convex mesh's faces: n . x + d <= 0 inside."""
    normals = np.asarray(part.face_normals, dtype=np.float64)
    keep = np.linalg.norm(normals, axis=1) > 0.5
    normals = normals[keep]
    offsets = -np.einsum("ij,ij->i", normals, np.asarray(part.triangles[keep, 0], dtype=np.float64))
    return np.column_stack([normals, offsets])


def finger_points(grasp_point_world: np.ndarray, axis_xy: np.ndarray, fingers: OpenFingers, spacing_m=0.005):
    """[N, 3] points filling both open fingers (world, m) with the TCP at grasp_point_world and the
    fingers closing along the horizontal unit axis_xy."""
    axis = np.asarray(axis_xy, dtype=np.float64)[:2]
    across = np.array([-axis[1], axis[0]])
    along_steps = np.linspace(-0.5, 0.5, max(2, int(np.ceil(fingers.thickness_m / spacing_m)) + 1))
    across_steps = np.linspace(-0.5, 0.5, max(2, int(np.ceil(fingers.width_m / spacing_m)) + 1))
    tip_z = float(grasp_point_world[2]) - fingers.tcp_above_tip_m
    heights = np.linspace(tip_z, tip_z + fingers.length_m, max(2, int(np.ceil(fingers.length_m / spacing_m)) + 1))
    a, b, z = np.meshgrid(along_steps * fingers.thickness_m, across_steps * fingers.width_m, heights, indexing="ij")
    offset_xy = a.reshape(-1, 1) * axis + b.reshape(-1, 1) * across
    points, middle = [], np.asarray(grasp_point_world, dtype=np.float64)[:2]
    for side in (-1.0, 1.0):
        centre = middle + side * (0.5 * (fingers.gap_m + fingers.thickness_m)) * axis
        points.append(np.column_stack([centre + offset_xy, z.reshape(-1)]))
    return np.concatenate(points)


def palm_points(
    grasp_point_world: np.ndarray, axis_xy: np.ndarray, fingers: OpenFingers, spacing_m=0.01, layer_m=0.015
) -> np.ndarray:
    """[N, 3] points on the underside of the palm (and layer_m above it) of a hand pointing down with
    its TCP at grasp_point_world and its fingers closing along the horizontal unit axis_xy (world, m);
    none when the palm is unknown."""
    if not fingers.palm_known:
        return np.zeros((0, 3))
    axis = np.asarray(axis_xy, dtype=np.float64)[:2]
    axis = axis / (np.linalg.norm(axis) + 1e-12)
    across = np.array([-axis[1], axis[0]])
    along_steps = np.linspace(-0.5, 0.5, int(np.ceil(fingers.palm_length_m / spacing_m)) + 1) * fingers.palm_length_m
    across_steps = np.linspace(-0.5, 0.5, int(np.ceil(fingers.palm_width_m / spacing_m)) + 1) * fingers.palm_width_m
    bottom = float(grasp_point_world[2]) + fingers.length_m - fingers.tcp_above_tip_m
    a, b, z = np.meshgrid(along_steps, across_steps, [bottom, bottom + layer_m], indexing="ij")
    xy = np.asarray(grasp_point_world, dtype=np.float64)[:2] + a.reshape(-1, 1) * axis + b.reshape(-1, 1) * across
    return np.column_stack([xy, z.reshape(-1)])


def hand_points(grasp_point_world: np.ndarray, axis_xy: np.ndarray, fingers: OpenFingers) -> np.ndarray:
    """[N, 3] the open fingers' points (finger_points) and the palm's (palm_points), world m."""
    return np.concatenate(
        [finger_points(grasp_point_world, axis_xy, fingers), palm_points(grasp_point_world, axis_xy, fingers)]
    )


def clearance_m(points_world: np.ndarray, obstacle_halfspaces: list[np.ndarray]) -> float:
    """The points' smallest clearance from the obstacles (m): per part the largest plane distance, a
    lower bound on the true distance outside it and minus the depth inside it; inf without obstacles."""
    if not obstacle_halfspaces:
        return float("inf")
    planes = np.concatenate(obstacle_halfspaces)
    signed = points_world @ planes[:, :3].T + planes[:, 3]  # [points, planes]
    starts = np.concatenate([[0], np.cumsum([len(h) for h in obstacle_halfspaces])[:-1]])
    return float(np.maximum.reduceat(signed, starts, axis=1).min())  # min over points and parts


def clear_closing_axis(
    grasp_point_world: np.ndarray,
    preferred_axis_xy: np.ndarray,
    fingers: OpenFingers,
    obstacle_halfspaces: list[np.ndarray],
    fits=lambda axis_xy: True,
    blocked_below_m: float = 0.0,
    wanted_m: float = 0.01,
    candidates: int = 12,
) -> np.ndarray:
    """The closing axis (unit, horizontal, [3] with z 0): the preferred one unless a finger would come
    within blocked_below_m of an obstacle (0: only where it would certainly enter one); then, of
    `candidates` axes over half a turn that `fits` (the target fits between the fingers along it), the
    nearest to the preferred one with wanted_m of clearance, or else the clearest. The palm counts
    as the fingers do: a tall neighbour under it holds the hand up as well."""
    given = np.asarray(preferred_axis_xy, dtype=np.float64)
    kept = np.append(given[:2], 0.0)  # returned as given (a unit axis): a clear grasp plans exactly as before
    preferred = given[:2] / (np.linalg.norm(given[:2]) + 1e-12)
    if not fingers.known or not obstacle_halfspaces:
        return kept
    preferred_clearance = clearance_m(hand_points(grasp_point_world, preferred, fingers), obstacle_halfspaces)
    if preferred_clearance >= blocked_below_m:
        return kept
    start = np.arctan2(preferred[1], preferred[0])
    turns = np.pi * np.arange(1, candidates) / candidates
    turns = np.where(turns > np.pi / 2, turns - np.pi, turns)  # signed turn from the preferred axis
    best, best_clearance, best_turn = kept[:2], preferred_clearance, 0.0
    for turn in turns[np.argsort(np.abs(turns), kind="stable")]:
        axis = np.array([np.cos(start + turn), np.sin(start + turn)])
        if not fits(axis):
            continue
        clearance = clearance_m(hand_points(grasp_point_world, axis, fingers), obstacle_halfspaces)
        if clearance >= wanted_m:
            return np.append(axis, 0.0)
        if clearance > best_clearance + 1e-6 or (abs(clearance - best_clearance) <= 1e-6 and abs(turn) < best_turn):
            best, best_clearance, best_turn = axis, clearance, abs(turn)
    return np.append(best, 0.0)


def finger_points_in_hand(fingers: OpenFingers, spacing_m: float = 0.01) -> np.ndarray:
    """[N, 3] points filling both open fingers in the hand frame (m): origin at the TCP, y the
    closing axis, z the approach axis (towards the fingertips)."""
    upright = finger_points(np.zeros(3), np.array([1.0, 0.0]), fingers, spacing_m)  # closing axis x, z up
    return np.column_stack([upright[:, 1], upright[:, 0], -upright[:, 2]])


@dataclass(frozen=True)
class DepthGrid:
    """How deep each voxel (edge voxel_m, metres) of a box starting at origin_world lies inside a
    body, measured straight down from its upper surface: 0 outside, else how far the voxel lies under
    the top of the material above it in its column (m). A finger that comes down on a thin rim or
    wall is as deep in it as it has pushed down (the distance to the nearest surface would never
    exceed half the wall's thickness); one in a cup's open mouth is in nothing."""

    origin_world: np.ndarray
    voxel_m: float
    depth_m: np.ndarray  # [nx, ny, nz]

    @classmethod
    def from_filled(cls, origin_world: np.ndarray, voxel_m: float, filled: np.ndarray) -> DepthGrid:
        """The grid of a voxelised body (filled: [nx, ny, nz] bool, z up)."""
        filled = np.asarray(filled, dtype=bool)
        z = np.arange(filled.shape[2])
        empty_z = np.where(filled, filled.shape[2], z)  # the box's top counts as empty above
        first_empty_above = np.flip(np.minimum.accumulate(np.flip(empty_z, axis=2), axis=2), axis=2)
        depth = np.where(filled, (first_empty_above - z - 0.5) * voxel_m, 0.0)
        return cls(np.asarray(origin_world, dtype=np.float64), float(voxel_m), depth)

    def depth_at(self, points_world: np.ndarray) -> np.ndarray:
        """[...] depth of each point [..., 3] inside the body (m); 0 outside the box."""
        index = np.floor((points_world - self.origin_world) / self.voxel_m).astype(np.int64)
        valid = np.all((index >= 0) & (index < np.array(self.depth_m.shape)), axis=-1)
        index = np.where(valid[..., None], index, 0)
        return np.where(valid, self.depth_m[index[..., 0], index[..., 1], index[..., 2]], 0.0)


def deepest_finger_m(hand_pos: np.ndarray, hand_rot: np.ndarray, finger_points_hand: np.ndarray, grid: DepthGrid):
    """[...] the deepest any open-finger point (finger_points_in_hand) of a hand at hand_pos [..., 3]
    (world, m) with rotation hand_rot [..., 3, 3] lies inside the grid's body (m)."""
    points = hand_pos[..., None, :] + np.einsum("...ij,nj->...ni", hand_rot, finger_points_hand)
    return grid.depth_at(points).max(axis=-1)


def hand_pointing_down(axis_xy: np.ndarray) -> np.ndarray:
    """[3, 3] rotation of a hand pointing straight down with its fingers closing along axis_xy."""
    along = np.append(np.asarray(axis_xy, dtype=np.float64)[:2], 0.0)
    along /= np.linalg.norm(along) + 1e-12
    approach = np.array([0.0, 0.0, -1.0])
    return np.column_stack([np.cross(along, approach), along, approach])


class FingerIntrusion:
    """How much deeper than allowed the open fingers of a hand stand in a target as it stood when
    this was made (m): a finger that comes down on a tall or top-heavy object tips it over.

    The target is a depth grid of it (DepthGrid: how far a finger has pushed down into it); the
    allowance is how deep the fingers stand at the hand's goal pose (hand_goal_pos, hand_goal_rot)
    plus allowance_m, so the goal itself costs nothing."""

    def __init__(
        self,
        fingers: OpenFingers,
        target_depth: DepthGrid,
        hand_goal_pos: np.ndarray,
        hand_goal_rot: np.ndarray,
        allowance_m: float = 0.004,
        finger_spacing_m: float = 0.015,
    ):
        self.grid = target_depth
        self.finger_points_hand = finger_points_in_hand(fingers, finger_spacing_m)
        at_goal = deepest_finger_m(np.asarray(hand_goal_pos), hand_goal_rot, self.finger_points_hand, self.grid)
        self.allowed_m = float(at_goal) + allowance_m

    def __call__(self, hand_pos: np.ndarray, hand_rot: np.ndarray) -> np.ndarray:
        """[...] the excess depth (m) for hands at hand_pos [..., 3] with rotations hand_rot [..., 3, 3]."""
        depth = deepest_finger_m(hand_pos, hand_rot, self.finger_points_hand, self.grid)
        return np.maximum(depth - self.allowed_m, 0.0)
