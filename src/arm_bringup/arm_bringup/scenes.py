"""Reconstructed and ground-truth objects as simulator scenes: meshes in the world frame, renders,
and the Chamfer distance of each reconstruction to the closest true object."""

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from arm_interfaces.msg import ReconstructedObjectArray
from arm_ros.conversions.meshes import reconstructed_object_from_msg
from arm_sim.objects import ObjectModel
from arm_sim.scenes import PlacedObject, Scene
from arm_sim.world import SimWorld


def chamfer_m(mesh_a, mesh_b, samples: int = 3000) -> float:
    """Symmetric Chamfer distance: the mean over both directions of the mean nearest-neighbour
    distance between points sampled uniformly on the two surfaces, metres."""
    a, b = mesh_a.sample(samples), mesh_b.sample(samples)
    return 0.5 * float(cKDTree(b).query(a)[0].mean() + cKDTree(a).query(b)[0].mean())


def objects_to_scene(msg: ReconstructedObjectArray) -> tuple[Scene, list]:
    objects, meshes = [], []
    for obj in msg.objects:
        T, (v, f), parts = reconstructed_object_from_msg(obj)
        mesh = trimesh.Trimesh(v, f, process=False)
        world = mesh.copy().apply_transform(T)
        hulls = [trimesh.Trimesh(pv, pf, process=False) for pv, pf in parts] or [mesh.convex_hull]
        colour = tuple(np.random.default_rng(obj.id).uniform(0.2, 0.9, 3)) + (1.0,)
        objects.append(PlacedObject(ObjectModel(f"id{obj.id}", "msg", mesh, hulls), 1.0, T, colour))
        meshes.append((obj.id, world))
    return Scene(objects, msg.table_height_m), meshes


def render_scene_rgb(msg: ReconstructedObjectArray, T_world_camera) -> np.ndarray:
    scene, _ = objects_to_scene(msg)
    world = SimWorld(scene, robot_arm=False)
    rgb = world.render(T_world_camera, with_visibility=False).rgb
    world.close()
    return rgb


def reconstruction_errors(meshes: ReconstructedObjectArray, truth: ReconstructedObjectArray) -> dict:
    """Each reconstructed object matched to the true object with the closest centroid, and its
    Chamfer distance to it."""
    _, recon = objects_to_scene(meshes)
    _, gt = objects_to_scene(truth)
    errors = []
    for rid, rmesh in recon:
        centre = rmesh.centroid
        gid, gmesh = min(gt, key=lambda g: np.linalg.norm(g[1].centroid - centre))
        errors.append({"id": rid, "matched_truth_id": gid, "chamfer_m": round(chamfer_m(rmesh, gmesh), 4)})
    return {
        "objects": len(recon),
        "per_object": errors,
        "mean_chamfer_m": float(np.mean([e["chamfer_m"] for e in errors] or [np.nan])),
    }
