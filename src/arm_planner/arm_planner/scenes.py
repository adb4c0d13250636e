"""The last few reconstructed scenes a planner received, keyed by the stamp of their source frame.

Object ids are the segmentation labels of one frame, so an id means nothing without the scene it was
read from: a client names that scene by its stamp, and a re-plan on a newer scene finds the same
object again by position.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from arm_planner.twin import TwinObject


@dataclass(frozen=True)
class Scene:
    """Objects reconstructed from one frame. stamp_ns: the source frame's stamp, ns (0: unstamped)."""

    objects: list[TwinObject]
    table_height_m: float
    stamp_ns: int = 0
    dropped: dict[int, str] = field(default_factory=dict)

    def centre_world(self, object_id: int) -> np.ndarray | None:
        """World position of an object's frame origin (its mesh centroid), m; None if absent."""
        for obj in self.objects:
            if obj.id == object_id:
                return np.asarray(obj.T_world_object, dtype=np.float64)[:3, 3]
        return None


class SceneHistory:
    """Bounded history of scenes, newest last."""

    def __init__(self, capacity: int = 10):
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity}")
        self._scenes: deque[Scene] = deque(maxlen=capacity)

    def __len__(self) -> int:
        return len(self._scenes)

    def add(self, scene: Scene) -> None:
        self._scenes.append(scene)

    def latest(self) -> Scene | None:
        return self._scenes[-1] if self._scenes else None

    def stamped(self, stamp_ns: int) -> Scene | None:
        """The newest scene with this stamp; stamp 0 selects the latest scene."""
        if stamp_ns == 0:
            return self.latest()
        return next((s for s in reversed(self._scenes) if s.stamp_ns == stamp_ns), None)

    def stamps_ns(self) -> list[int]:
        return [s.stamp_ns for s in self._scenes]


def nearest_object(scene: Scene, points_m, max_distance_m: float) -> TwinObject | None:
    """The object of `scene` whose centre is nearest any of `points_m` ([k, 3] or [3], world, m), if
    within max_distance_m."""
    if not scene.objects:
        return None
    centres = np.array([np.asarray(o.T_world_object)[:3, 3] for o in scene.objects])
    points = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    distances = np.linalg.norm(centres[:, None, :] - points[None, :, :], axis=2).min(axis=1)
    nearest = int(np.argmin(distances))
    return scene.objects[nearest] if distances[nearest] <= max_distance_m else None


def follow_target(previous: Scene, target_id: int, newer: Scene, max_distance_m: float) -> int | None:
    """Id in `newer` of the object `target_id` of `previous`: the object whose centre is nearest the
    target's old centre, if within max_distance_m (m); None when none is."""
    old = previous.centre_world(target_id)
    found = None if old is None else nearest_object(newer, old, max_distance_m)
    return None if found is None else int(found.id)


def observed_displacement(
    previous: Scene, target_id: int, newer: Scene, expected_m, max_distance_m: float
) -> np.ndarray | None:
    """How far the target `target_id` of `previous` moved by `newer` (world, m): its centre there is the
    object nearest either where it was or where the task should have put it (old centre + expected_m),
    within max_distance_m, and nearer those than any other object of `previous` (a neighbour that did
    not move is not the target); None when there is no such object (a target held in the hand and
    hidden by it, or gone from view)."""
    old = previous.centre_world(target_id)
    if old is None:
        return None
    places = np.stack([old, old + np.asarray(expected_m, dtype=np.float64)])
    found = nearest_object(newer, places, max_distance_m)
    if found is None:
        return None
    centre = np.asarray(found.T_world_object, dtype=np.float64)[:3, 3]
    others = [np.asarray(o.T_world_object)[:3, 3] for o in previous.objects if o.id != target_id]
    to_target = np.linalg.norm(places - centre, axis=1).min()
    if others and np.linalg.norm(np.array(others) - centre, axis=1).min() <= to_target:
        return None
    return centre - old
