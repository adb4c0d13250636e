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
    tip to palm, and the TCP's height above the tips (metres)."""

    gap_m: float
    thickness_m: float
    width_m: float
    length_m: float
    tcp_above_tip_m: float

    @property
    def known(self) -> bool:
        return min(self.gap_m, self.thickness_m, self.width_m, self.length_m) > 0


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
    nearest to the preferred one with wanted_m of clearance, or else the clearest."""
    given = np.asarray(preferred_axis_xy, dtype=np.float64)
    kept = np.append(given[:2], 0.0)  # returned as given (a unit axis): a clear grasp plans exactly as before
    preferred = given[:2] / (np.linalg.norm(given[:2]) + 1e-12)
    if not fingers.known or not obstacle_halfspaces:
        return kept
    preferred_clearance = clearance_m(finger_points(grasp_point_world, preferred, fingers), obstacle_halfspaces)
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
        clearance = clearance_m(finger_points(grasp_point_world, axis, fingers), obstacle_halfspaces)
        if clearance >= wanted_m:
            return np.append(axis, 0.0)
        if clearance > best_clearance + 1e-6 or (abs(clearance - best_clearance) <= 1e-6 and abs(turn) < best_turn):
            best, best_clearance, best_turn = axis, clearance, abs(turn)
    return np.append(best, 0.0)
