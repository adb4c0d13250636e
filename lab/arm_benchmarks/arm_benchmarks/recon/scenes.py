"""bench_recon's scenes and views, and the objects it evaluates in them."""

from __future__ import annotations

import numpy as np

from arm_benchmarks.recon.config import MAX_VIEW_TRIES, OCCLUDED_VISIBILITY, BenchConfig
from arm_core.camera import silhouette
from arm_planner.twin import TwinObject
from arm_reconstruction.convex_parts import ConvexDecomposer
from arm_sim.views import BenchmarkScene


def evaluated_ids(labels, depth_m, min_pixels: int) -> list[int]:
    """Instance ids with at least min_pixels pixels that carry depth, ascending."""
    counts = np.bincount(np.asarray(labels)[np.asarray(depth_m) > 0].ravel().astype(np.int64))
    return [int(i) for i in np.flatnonzero(counts >= min_pixels) if i > 0]


def _occlusion_score(frame, min_pixels: int) -> tuple[int, int]:
    ids = np.asarray(evaluated_ids(frame.labels, frame.depth_m, min_pixels), dtype=np.int64)
    occluded = int(np.count_nonzero(frame.visible_fraction[ids - 1] < OCCLUDED_VISIBILITY)) if len(ids) else 0
    return occluded, len(ids)


def render_scene(index: int, config: BenchConfig, pool):
    """Scene `index` (deterministic in seed and index) and its view: view 'random' takes the first
    random view that shows an object to evaluate; 'occluded' renders view_candidates such views and
    keeps the one with the most evaluated objects below OCCLUDED_VISIBILITY visible (then the most
    evaluated objects), to populate the low-visibility bins."""
    rng = np.random.default_rng([config.seed, index])
    scale_range = (1.0, 1.0) if config.objects else (0.5, 2.0)
    wanted = config.view_candidates if config.view == "occluded" else 1
    best, best_score, found = None, (-1, -1), 0
    with BenchmarkScene(
        pool,
        rng,
        (config.min_objects, config.max_objects),
        depth_noise=config.depth_noise,
        scale_range=scale_range,
        domain=config.domain,
    ) as views:
        for _ in range(MAX_VIEW_TRIES * wanted):
            frame = views.render()
            score = _occlusion_score(frame, config.min_visible_pixels)
            if score[1] == 0:
                continue
            if score > best_score:
                best, best_score = frame, score
            found += 1
            if found == wanted:
                break
    return views.scene, best if best is not None else frame


def object_silhouette(placed, K, T_world_camera, shape) -> np.ndarray:
    """bool image of the pixels a placed object covers when rendered alone (its convex parts)."""
    T = np.asarray(placed.T_world_object, dtype=np.float64)
    parts = [np.asarray(vertices) @ T[:3, :3].T + T[:3, 3] for vertices, _ in placed.convex_parts_local()]
    return silhouette(parts, K, T_world_camera, shape[1], shape[0])


def twin_object(object_id: int, T_world_object, mesh, parts) -> TwinObject:
    return TwinObject(int(object_id), np.asarray(T_world_object, dtype=np.float64), mesh, list(parts))


def ground_truth_objects(scene, ids, decomposer: ConvexDecomposer) -> list[TwinObject]:
    """The true meshes of the objects `ids` (label = index + 1) as the pipeline outputs objects: frame
    parallel to the world at the centroid, convex parts from the pipeline's decomposer."""
    objects = []
    for object_id in ids:
        world = scene.objects[object_id - 1].world_mesh()
        T = np.eye(4)
        T[:3, 3] = world.center_mass if world.is_watertight else world.vertices.mean(0)
        local = world.copy().apply_translation(-T[:3, 3])
        objects.append(twin_object(object_id, T, local, decomposer(local)))
    return objects


def simulator_part_objects(scene, ids) -> list[TwinObject]:
    """The objects `ids` with the convex parts the simulator itself uses (not re-decomposed)."""
    objects = []
    for object_id in ids:
        placed = scene.objects[object_id - 1]
        parts = placed.model.convex_parts or [placed.model.mesh.convex_hull]
        mesh = placed.model.mesh.copy().apply_scale(placed.scale)
        scaled = [p.copy().apply_scale(placed.scale) for p in parts]
        objects.append(twin_object(object_id, placed.T_world_object, mesh, scaled))
    return objects
