"""Physical stability of a view's objects: built as the planner's twin builds them, settled under gravity."""

from __future__ import annotations

import mujoco
import numpy as np
import trimesh

from arm_planner.twin import usable_parts
from arm_sim.objects import ObjectModel
from arm_sim.scenes import PlacedObject, Scene
from arm_sim.world import build_world, object_body_ids


def scene_stability(
    objects, table_height_m: float, table_half_extent_m, duration_s: float = 5.0, timestep_s: float = 0.01
) -> dict[int, float]:
    """id -> L2 displacement (m) of each object's centre of mass after duration_s of gravity alone.

    objects: arm_planner.twin.TwinObject (object-frame mesh and convex parts, T_world_object). The
    scene is built as the planner's twin builds it, without the robot and with every pair of objects
    colliding (the twin lets objects overlapping as built pass through each other); objects the twin would skip
    (no usable convex part) are absent from the result. A diverging simulation gives inf."""
    placed, ids = [], []
    for obj in objects:
        T = np.asarray(obj.T_world_object, dtype=np.float64)
        parts = usable_parts(obj)
        if not parts or not np.all(np.isfinite(T)):
            continue
        mesh = obj.mesh if obj.mesh is not None and len(obj.mesh.vertices) else trimesh.util.concatenate(parts)
        model = ObjectModel(f"recon_{obj.id}", "reconstructed", mesh, parts)
        placed.append(PlacedObject(model, 1.0, T, (0.6, 0.6, 0.6, 1.0)))
        ids.append(int(obj.id))
    if not placed:
        return {}
    scene = Scene(objects=placed, table_height_m=float(table_height_m), table_half_extent_m=tuple(table_half_extent_m))
    model = build_world(scene, robot_arm=False, timestep_s=timestep_s, name="arm_stability")
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    bodies = object_body_ids(model, len(placed))
    start = data.xipos[bodies].copy()
    mujoco.mj_step(model, data, nstep=int(round(duration_s / timestep_s)))
    moved = np.linalg.norm(data.xipos[bodies] - start, axis=1)
    moved = np.where(np.isfinite(moved), moved, np.inf)
    return dict(zip(ids, moved.tolist(), strict=True))
