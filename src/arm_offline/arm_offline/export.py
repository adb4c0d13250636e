"""Outputs of one reconstructed frame: object meshes and convex parts, and the MJCF scene.

The MJCF comes from arm_sim's world builder (the same code path as the simulator and the planner's
twin): the table box, the floor and one free body per object with its convex parts as collision
geoms; no robot. As in the twin, two objects whose convex parts overlap as built do not collide.
The builder centres the table at the world origin, so the table box is made large
enough to cover the support plane's footprint and the objects.
"""

import pathlib
from dataclasses import dataclass

import numpy as np
import trimesh

from arm_core.camera import transform_points
from arm_reconstruction.pipeline import ReconstructedObject
from arm_segmentation.refine import instance_colours
from arm_sim.objects import ObjectModel
from arm_sim.scenes import PlacedObject, Scene
from arm_sim.world import compile_without_overlap_contacts, object_body_name, world_spec

MESH_FORMATS = ("ply", "obj", "stl", "glb")  # ply, obj and glb carry the vertex colours
MIN_PART_VOLUME_M3 = 1e-10  # MuJoCo's mesh compiler rejects flat hulls
TABLE_MARGIN_M = 0.05
DEFAULT_TABLE_HALF_EXTENT_M = (0.7, 0.5)


class SceneError(RuntimeError):
    """MuJoCo does not compile the reconstructed scene."""


@dataclass
class ExportedObject:
    """A reconstructed object as the frame's outputs write it: its mesh in the world frame (with its
    vertex colours) and the convex parts the MJCF scene collides with (object frame), each made once."""

    obj: ReconstructedObject
    world_mesh: trimesh.Trimesh
    parts: list[trimesh.Trimesh]


def exported_objects(objects: list[ReconstructedObject]) -> list[ExportedObject]:
    """The objects that were reconstructed, ready to write."""
    return [ExportedObject(obj, obj.world_mesh(), simulation_parts(obj)) for obj in objects if obj.ok]


def write_object_meshes(exported: ExportedObject, folder: pathlib.Path, mesh_format: str) -> dict:
    """object_<id>.<fmt> and object_<id>_part_<j>.<fmt> (the parts the MJCF scene collides with), in
    the world frame (metres)."""
    obj = exported.obj
    mesh_path = folder / f"object_{obj.id}.{mesh_format}"
    exported.world_mesh.export(mesh_path)
    part_paths = []
    for j, part in enumerate(exported.parts):
        part_paths.append(folder / f"object_{obj.id}_part_{j}.{mesh_format}")
        world_part = trimesh.Trimesh(transform_points(part.vertices, obj.T_world_object), part.faces, process=False)
        world_part.export(part_paths[-1])
    return {"mesh": mesh_path.name, "convex_parts": [p.name for p in part_paths]}


def simulation_parts(obj: ReconstructedObject) -> list[trimesh.Trimesh]:
    return [p for p in obj.convex_parts if len(p.vertices) >= 4 and abs(p.volume) > MIN_PART_VOLUME_M3]


def mean_colours(rgb: np.ndarray, labels: np.ndarray, n_labels: int) -> np.ndarray:
    """(n_labels, 4) RGBA (0..1) of the mean colour of the pixels of each label 0..n_labels - 1 (grey
    where there are none), from one pass over the image."""
    present = np.bincount(labels.ravel(), minlength=n_labels)[:n_labels] > 0
    means = np.zeros((n_labels, 3))
    found = instance_colours(labels, rgb)[:n_labels]
    means[: len(found)] = found
    return np.column_stack([np.where(present[:, None], means / 255.0, 0.6), np.ones(n_labels)])


def table_half_extent_m(objects: list[ExportedObject], support_xy: np.ndarray | None) -> tuple[float, float]:
    """Half extents of an origin-centred table box covering the support footprint and the objects."""
    xy = [np.asarray(support_xy).reshape(-1, 2)] if support_xy is not None else []
    xy += [exported.world_mesh.bounds[:, :2] for exported in objects]
    if not any(len(a) for a in xy):
        return DEFAULT_TABLE_HALF_EXTENT_M
    reach = np.abs(np.concatenate(xy)).max(axis=0) + TABLE_MARGIN_M
    return float(reach[0]), float(reach[1])


def scene_mjcf(
    objects: list[ExportedObject],
    rgb: np.ndarray,
    labels: np.ndarray,
    table_mask: np.ndarray,
    table_height_m: float,
    support_xy: np.ndarray | None,
    name: str,
) -> tuple[str, dict[int, str]]:
    """(MJCF text, {object id: body name}) of the table and the objects with usable convex parts.
    Raises SceneError with MuJoCo's message if the model does not compile."""
    placed, bodies = [], {}
    simulated = [exported for exported in objects if exported.parts]
    colours = mean_colours(rgb, labels, max([e.obj.id for e in simulated], default=0) + 1)
    for exported in simulated:
        obj = exported.obj
        model = ObjectModel(f"recon_{obj.id}", "reconstructed", obj.mesh, exported.parts)
        placed.append(PlacedObject(model, 1.0, obj.T_world_object, tuple(float(c) for c in colours[obj.id])))
        bodies[obj.id] = object_body_name(len(placed) - 1)
    table_rgba = tuple(float(c) for c in mean_colours(rgb, table_mask.astype(np.uint8), 2)[1])
    scene = Scene(placed, float(table_height_m), table_half_extent_m(simulated, support_xy), table_rgba)
    spec = world_spec(scene, robot_arm=False, name=f"reconstruction_{name}")
    try:  # as in the planner's twin: objects overlapping as built do not collide with each other
        compile_without_overlap_contacts(spec, len(placed))
    except ValueError as error:  # MuJoCo's compiler reports through ValueError
        raise SceneError(f"the MJCF scene does not compile: {error}") from error
    return spec.to_xml(), bodies
