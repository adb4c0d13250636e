"""A reconstructed frame's own MJCF scene (scene.xml as reconstruct_frames writes it): does each object
stand, and what does the scene look like from the camera and from the side after the physics."""

from dataclasses import dataclass

import mujoco
import numpy as np

from arm_core.camera import look_at
from arm_sim.world import RENDER_CAMERA, object_body_ids, place_camera

STABLE_MOVE_M = 0.02
STABLE_TURN_DEG = 15.0
REST_TOLERANCE_M = 0.02  # an object's lowest point this close to the support or to another object rests on it


@dataclass
class ObjectMotion:
    body: str
    moved_m: float
    turned_deg: float
    bottom_above_table_m: float  # lowest point of its collision geoms above the table top, before the physics
    resting: bool  # its lowest point touches the table or another object (within REST_TOLERANCE_M)

    @property
    def stable(self) -> bool:
        return self.moved_m < STABLE_MOVE_M and self.turned_deg < STABLE_TURN_DEG


def _object_bodies(model: mujoco.MjModel) -> list[int]:
    """The scene's object bodies (arm_sim.world's object_<i>), in order."""
    n_objects = sum(model.body(b).name.startswith("object_") for b in range(model.nbody))
    return object_body_ids(model, n_objects).tolist()


def _geom_z_range(model: mujoco.MjModel, data: mujoco.MjData, geom: int) -> tuple[float, float]:
    """(lowest, highest) world z of a geom: its mesh vertices, or its bounding sphere otherwise."""
    if model.geom_type[geom] != mujoco.mjtGeom.mjGEOM_MESH:
        z, r = float(data.geom_xpos[geom][2]), float(model.geom_rbound[geom])
        return z - r, z + r
    mesh = model.geom_dataid[geom]
    start, count = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
    vertices = model.mesh_vert[start : start + count].astype(np.float64)
    z = (vertices @ data.geom_xmat[geom].reshape(3, 3).T + data.geom_xpos[geom])[:, 2]
    return float(z.min()), float(z.max())


def _resting(model, data, body: int, bottom_z: float, table_z: float, bodies: list[int]) -> bool:
    """Lowest point on the table, or on the top of another object's geom under it (xy overlap)."""
    if abs(bottom_z - table_z) <= REST_TOLERANCE_M:
        return True
    own = np.flatnonzero(model.geom_bodyid == body)
    lo = np.min([data.geom_xpos[g][:2] - model.geom_rbound[g] for g in own], axis=0)
    hi = np.max([data.geom_xpos[g][:2] + model.geom_rbound[g] for g in own], axis=0)
    for other in bodies:
        if other == body:
            continue
        for g in np.flatnonzero(model.geom_bodyid == other):
            centre, r = data.geom_xpos[g][:2], model.geom_rbound[g]
            overlaps = np.all(centre + r >= lo) and np.all(centre - r <= hi)
            if overlaps and abs(_geom_z_range(model, data, g)[1] - bottom_z) <= REST_TOLERANCE_M:
                return True
    return False


def settle_scene(model: mujoco.MjModel, duration_s: float) -> tuple[mujoco.MjData, list[ObjectMotion]]:
    """Runs duration_s of gravity on a scene; each object body's motion (in body order)."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    bodies = _object_bodies(model)
    table = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "table")
    table_z = float(data.geom_xpos[table][2] + model.geom_size[table][2]) if table >= 0 else 0.0
    bottoms = [
        min(_geom_z_range(model, data, g)[0] for g in np.flatnonzero(model.geom_bodyid == body)) for body in bodies
    ]
    resting = [_resting(model, data, b, z, table_z, bodies) for b, z in zip(bodies, bottoms, strict=True)]
    start_pos = data.xpos[bodies].copy()
    start_rot = data.xmat[bodies].reshape(-1, 3, 3).copy()
    mujoco.mj_step(model, data, nstep=int(round(duration_s / model.opt.timestep)))
    moved = np.linalg.norm(data.xpos[bodies] - start_pos, axis=1)
    relative = np.einsum("nji,njk->nik", start_rot, data.xmat[bodies].reshape(-1, 3, 3))
    cos = np.clip((np.trace(relative, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    turned = np.degrees(np.arccos(cos))
    motions = [
        ObjectMotion(
            model.body(b).name,
            float(m) if np.isfinite(m) else np.inf,
            float(t) if np.isfinite(t) else 180.0,
            float(z - table_z),
            bool(r),
        )
        for b, m, t, z, r in zip(bodies, moved, turned, bottoms, resting, strict=True)
    ]
    return data, motions


def side_view_pose(T_world_camera: np.ndarray, target_world: np.ndarray, elevation_deg: float = 15.0) -> np.ndarray:
    """A camera beside the scene: at the real camera's distance from target, turned 90 degrees about
    the vertical, looking at target from elevation_deg above the table plane."""
    offset = T_world_camera[:3, 3] - target_world
    distance = max(float(np.linalg.norm(offset)), 0.4)
    heading = np.arctan2(offset[1], offset[0]) + np.pi / 2
    elevation = np.radians(elevation_deg)
    direction = np.array([np.cos(heading) * np.cos(elevation), np.sin(heading) * np.cos(elevation), np.sin(elevation)])
    return look_at(target_world + distance * direction, target_world)


def render_views(
    model: mujoco.MjModel, data: mujoco.MjData, poses: list[np.ndarray], K: np.ndarray, width: int, height: int
) -> list[np.ndarray]:
    """RGB renders (uint8) of the scene from each optical-frame pose, with K's vertical field of view."""
    camera = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, RENDER_CAMERA)
    model.cam_fovy[camera] = float(np.degrees(2.0 * np.arctan(0.5 * height / K[1, 1])))
    width, height = min(width, model.vis.global_.offwidth), min(height, model.vis.global_.offheight)
    images = []
    with mujoco.Renderer(model, height, width) as renderer:
        for T in poses:
            place_camera(model, data, camera, T)
            renderer.update_scene(data, camera=camera)
            images.append(renderer.render().copy())
    return images
