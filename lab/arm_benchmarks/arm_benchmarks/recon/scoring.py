"""bench_recon's scoring: every method reconstructs a view's objects, which are scored against the
true meshes (Chamfer, IoU) and for physical stability; the true meshes go through the same physics."""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import pathlib
import time

import numpy as np
import torch

from arm_benchmarks.methods import GROUND_TRUTH
from arm_benchmarks.recon.config import QUALITATIVE_MAX_VISIBILITY, QUALITATIVE_PER_SCENE, VISIBLE_ONLY, BenchConfig
from arm_benchmarks.recon.matching import match_instances
from arm_benchmarks.recon.physics import scene_stability
from arm_benchmarks.recon.scenes import (
    evaluated_ids,
    ground_truth_objects,
    object_silhouette,
    render_scene,
    simulator_part_objects,
    twin_object,
)
from arm_core.boxes import mask_box
from arm_reconstruction.checkpoint import CheckpointError
from arm_reconstruction.convex_parts import ConvexDecomposer, DecompositionSettings
from arm_reconstruction.grid import DEFAULT_K, DEFAULT_RESOLUTION
from arm_reconstruction.metrics import chamfer_distance_m, normal_consistency, volumetric_iou
from arm_reconstruction.network import METHODS
from arm_reconstruction.pipeline import ReconstructionSettings, Reconstructor, StageTimer, resolve_checkpoint_path
from arm_segmentation.segmentation import segment


class VisibleOnly(Reconstructor):
    """'visible-only': each object's own observed voxels (grid channel F1) as its occupancy, without a
    network, meshed, de-intersected and decomposed by the pipeline's own stages."""

    def __init__(self, settings: ReconstructionSettings):
        self.settings = settings
        self.device = torch.device("cpu")
        self.resolution = int(settings.resolution or DEFAULT_RESOLUTION)
        self.k = float(settings.k or DEFAULT_K)
        self.decomposer = ConvexDecomposer(settings.decomposition)
        self.timer = StageTimer()
        self.checkpoint_config = {}

    def predict(self, grids):
        with self.timer("network"):
            return np.asarray(grids.grids[:, 0], dtype=np.float32)


def file_digest(path) -> str:
    return hashlib.sha256(pathlib.Path(path).read_bytes()).hexdigest()


def load_reconstructors(methods, checkpoint_dir: str = "", pipeline: dict | None = None) -> tuple[dict, dict, dict]:
    """-> (name -> Reconstructor, name -> reason skipped, name -> checkpoint path and sha256). Methods
    sharing a network variant share one loaded model; a missing or broken checkpoint skips its methods.
    pipeline: ReconstructionSettings fields every method shares (BenchConfig.pipeline(); {} = defaults)."""
    pipeline = pipeline or {}
    reconstructors, skipped, checkpoints, by_variant = {}, {}, {}, {}
    for name in methods:
        if name not in METHODS:
            continue
        settings = ReconstructionSettings(method=name, **pipeline)
        if checkpoint_dir:
            path = pathlib.Path(checkpoint_dir) / f"{settings.variant}.pt"
            settings = dataclasses.replace(settings, checkpoint_path=str(path))
        path = resolve_checkpoint_path(settings)
        try:
            if settings.variant in by_variant:
                shared = by_variant[settings.variant]
                reconstructor = Reconstructor(settings, model=shared.model)
                reconstructor.checkpoint_config = shared.checkpoint_config
            else:
                reconstructor = Reconstructor(settings)
                by_variant[settings.variant] = reconstructor
        except CheckpointError as error:
            skipped[name] = str(error)
            continue
        reconstructors[name] = reconstructor
        checkpoints[name] = {"path": str(path), "sha256": file_digest(path)}
    if VISIBLE_ONLY in methods:
        resolutions = [r.resolution for r in reconstructors.values()]
        resolution = reconstructors["arm"].resolution if "arm" in reconstructors else max(resolutions, default=0)
        k = reconstructors["arm"].k if "arm" in reconstructors else DEFAULT_K
        only_settings = ReconstructionSettings(
            method="baseline", resolution=resolution or DEFAULT_RESOLUTION, k=k, **pipeline
        )
        only = VisibleOnly(only_settings)
        reconstructors = {VISIBLE_ONLY: only, **reconstructors}
    return reconstructors, skipped, checkpoints


def _crop_box(mask: np.ndarray, pad: float = 0.25, min_px: int = 48) -> tuple[int, int, int, int]:
    h, w = mask.shape
    box = mask_box(mask)
    if box is None:
        return 0, h, 0, w
    r0, r1, c0, c1 = box[0].start, box[0].stop, box[1].start, box[1].stop
    half = max(min_px, int((1 + 2 * pad) * max(r1 - r0, c1 - c0))) // 2
    rc, cc = (r0 + r1) // 2, (c0 + c1) // 2
    return max(0, rc - half), min(h, rc + half), max(0, cc - half), min(w, cc + half)


def _qualitative_payload(scene, frame, object_id: int, meshes: dict) -> dict:
    full = object_silhouette(scene.objects[object_id - 1], frame.K, frame.T_world_camera, frame.labels.shape)
    visible = frame.labels == object_id
    r0, r1, c0, c1 = _crop_box(full | visible)
    payload = {
        "rgb": frame.rgb[r0:r1, c0:c1],
        "visible": visible[r0:r1, c0:c1],
        "silhouette": full[r0:r1, c0:c1],
        "camera_eye": frame.T_world_camera[:3, 3],
    }
    for name, mesh in meshes.items():
        payload[f"{name}/vertices"] = np.asarray(mesh.vertices, np.float32)
        payload[f"{name}/faces"] = np.asarray(mesh.faces, np.int32)
    return payload


def _score_method(reconstructor, grids, labels, frame, truths: dict, match: dict, table, config) -> tuple:
    """One method on one view -> ({truth id: metrics}, {truth id: reconstructed world mesh})."""
    probabilities = reconstructor.predict(grids)
    objects = reconstructor.build_objects(grids, probabilities, frame.depth_m, labels, frame.K, frame.T_world_camera)
    built = {o.id: o for o in objects if o.ok}
    twins = [twin_object(o.id, o.T_world_object, o.mesh, o.convex_parts) for o in built.values()]
    moved = scene_stability(twins, *table, config.settle_s, config.physics_timestep_s)
    entries, meshes = {}, {}
    for truth_id, truth in truths.items():
        obj = built.get(match.get(truth_id, -1))
        if obj is None:
            entries[truth_id] = {
                "empty": True,
                "chamfer_m": None,
                "normal_consistency": None,
                "iou": 0.0,
                "displacement_m": None,
            }
            continue
        mesh = meshes[truth_id] = obj.world_mesh()
        entry = entries[truth_id] = {
            "empty": False,
            "chamfer_m": chamfer_distance_m(mesh, truth, config.chamfer_samples),
            "normal_consistency": normal_consistency(mesh, truth, config.chamfer_samples),
            "displacement_m": moved.get(obj.id),
        }
        try:
            entry["iou"] = volumetric_iou(mesh, truth, config.iou_resolution)
        except ValueError as error:  # an open reconstructed surface has no defined inside
            entry |= {"iou": None, "iou_error": str(error)}
    return entries, meshes


def _score_ground_truth(scene, truth_ids, decomposition: DecompositionSettings, table, config) -> dict:
    """Displacements of the true meshes through the pipeline's decomposition, and with the simulator's parts."""
    run_physics = functools.partial(
        scene_stability,
        table_height_m=table[0],
        table_half_extent_m=table[1],
        duration_s=config.settle_s,
        timestep_s=config.physics_timestep_s,
    )
    moved = run_physics(ground_truth_objects(scene, truth_ids, ConvexDecomposer(decomposition)))
    moved_sim_parts = run_physics(simulator_part_objects(scene, truth_ids))
    return {
        i: {
            "empty": False,
            "chamfer_m": None,
            "normal_consistency": None,
            "iou": None,
            "displacement_m": moved.get(i),
            "displacement_sim_parts_m": moved_sim_parts.get(i),
        }
        for i in truth_ids
    }


def evaluate_scene(index: int, config: BenchConfig, pool, reconstructors: dict) -> tuple[dict, dict]:
    """Per-object metrics of every method on scene `index` -> (JSON-able result, qualitative arrays)."""
    start, start_cpu = time.perf_counter(), time.process_time()
    scene, frame = render_scene(index, config, pool)
    truth_ids = evaluated_ids(frame.labels, frame.depth_m, config.min_visible_pixels)
    if config.segmentation == "predicted":
        labels = segment(frame.rgb, frame.depth_m, frame.K, frame.T_world_camera)
        match = match_instances(labels, frame.labels, truth_ids)
        reconstruct_ids = evaluated_ids(labels, frame.depth_m, config.min_visible_pixels)
    else:
        labels, match, reconstruct_ids = frame.labels, {i: i for i in truth_ids}, truth_ids
    truths = {i: scene.objects[i - 1].world_mesh() for i in truth_ids}
    rows = {
        i: {
            "scene": index,
            "object": i - 1,
            "category": scene.objects[i - 1].model.category,
            "scale": float(scene.objects[i - 1].scale),
            "visible_fraction": float(frame.visible_fraction[i - 1]),
            "visible_pixels": int(np.count_nonzero((frame.labels == i) & (frame.depth_m > 0))),
            "matched": i in match,
            "methods": {},
        }
        for i in truth_ids
    }
    table = (scene.table_height_m, scene.table_half_extent_m)
    timing, grids_cache, kept = {}, {}, {i: {GROUND_TRUTH: truths[i]} for i in truth_ids}
    for name, reconstructor in reconstructors.items():
        tick = time.perf_counter()
        reconstructor.timer.reset()
        key = (reconstructor.resolution, reconstructor.k, reconstructor.settings.table_height_m)
        if key not in grids_cache:
            grids_cache[key] = reconstructor.grids(
                frame.depth_m, frame.K, frame.T_world_camera, labels, reconstruct_ids
            )
        entries, meshes = _score_method(reconstructor, grids_cache[key], labels, frame, truths, match, table, config)
        for i in truth_ids:
            rows[i]["methods"][name] = entries[i]
            if i in meshes:
                kept[i][name] = meshes[i]
        timing[name] = {"total_s": time.perf_counter() - tick}
    if GROUND_TRUTH in config.methods:
        tick = time.perf_counter()
        decomposition = next((r.settings.decomposition for r in reconstructors.values()), DecompositionSettings())
        for i, entry in _score_ground_truth(scene, truth_ids, decomposition, table, config).items():
            rows[i]["methods"][GROUND_TRUTH] = entry
        timing[GROUND_TRUTH] = {"total_s": time.perf_counter() - tick}
    qualitative = {}
    hard = sorted(
        (rows[i]["visible_fraction"], i)
        for i in truth_ids
        if rows[i]["visible_fraction"] < QUALITATIVE_MAX_VISIBILITY and {"baseline", "arm"} <= set(kept[i])
    )
    for n, (_, i) in enumerate(hard[:QUALITATIVE_PER_SCENE]):
        meshes = {m: kept[i][m] for m in ("baseline", "arm", GROUND_TRUTH)}
        for key, value in _qualitative_payload(scene, frame, i, meshes).items():
            qualitative[f"{n}/{key}"] = value
        qualitative[f"{n}/object"] = np.int64(i - 1)
    result = {
        "scene": index,
        "objects_in_scene": len(scene.objects),
        "objects_evaluated": len(rows),
        "segments_reconstructed": len(reconstruct_ids),
        "rows": list(rows.values()),
        "timing_s": timing,
        "wall_s": time.perf_counter() - start,
        "cpu_s": time.process_time() - start_cpu,
    }
    return result, qualitative
