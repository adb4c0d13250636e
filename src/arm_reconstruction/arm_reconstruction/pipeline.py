"""ARM inference path (paper Section 3.1): RGB-D frame + instance labels -> simulation-ready objects.

Stages (timed in Reconstructor.last_timings_s): four-channel grids of all objects (shared
back-projection), one batched network pass, method post-processing (ray carving / extrusion),
observed voxels the network missed added, thresholding + marching cubes, inter-object intersection
removal, convex decomposition and a visible-fraction estimate. Usable without ROS.
"""

import functools
import pathlib
import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np
import torch
import trimesh

from arm_core.camera import silhouette
from arm_core.frames import validate_frame
from arm_core.settings import setting

from .checkpoint import CheckpointError, default_checkpoint_path, load_checkpoint
from .colour import vertex_colours
from .convex_parts import ConvexDecomposer, DecompositionSettings
from .cuboid import CuboidSettings, cuboid_completion
from .grid import CHECKPOINT_DEFAULT_K, FrameGrids, GridFrame, GridInputError, frame_grids
from .meshing import (
    DEFAULT_MIN_COMPONENT_VOXELS,
    DEFAULT_SMOOTHING_ITERATIONS,
    DEFAULT_STABLE_BASE_TILT_DEG,
    DEFAULT_THRESHOLD,
    add_missed_observed_voxels,
    empty_mesh,
    extrude_to_table,
    occupancy_mesh,
    ray_carve,
    remove_intersections,
)
from .network import METHODS, canonical_method, predict_occupancy, prepare_for_inference, resolve_device
from .revolution import RevolutionSettings, revolution_completion
from .surface_snapping import SnapSettings, smoothed_object_depth, snap_to_observed_depth

STAGES = (
    "grid",
    "network",
    "postprocess",
    "meshing",
    "shapes",
    "snapping",
    "intersections",
    "decomposition",
    "visibility",
)


class ReconstructionPreempted(Exception):
    """The frame was abandoned between stages because Reconstructor.should_stop() said so."""


class StageTimer:
    """Wall-clock and process-CPU seconds (all threads) per stage, accumulated until reset()."""

    def __init__(self):
        self.reset()

    def reset(self) -> None:
        self.wall_s = dict.fromkeys(STAGES, 0.0)
        self.cpu_s = dict.fromkeys(STAGES, 0.0)

    @contextmanager
    def __call__(self, stage: str):
        wall, cpu = time.perf_counter(), time.process_time()
        try:
            yield
        finally:
            self.wall_s[stage] += time.perf_counter() - wall
            self.cpu_s[stage] += time.process_time() - cpu


@dataclass
class ReconstructedObject:
    """One reconstructed object. mesh and convex_parts are in the object frame, which is parallel to
    the world frame with its origin at the mesh's centroid (T_world_object). error is '' on success;
    otherwise the mesh is empty and error says why."""

    id: int
    T_world_object: np.ndarray
    mesh: trimesh.Trimesh
    convex_parts: list[trimesh.Trimesh]
    visible_fraction: float
    grid: GridFrame | None
    method: str
    error: str = ""
    probabilities: np.ndarray | None = field(default=None, repr=False)
    from_observed_voxels: bool = False  # the network predicted nothing: the mesh is of the observed voxels
    vertex_colours: np.ndarray | None = field(default=None, repr=False)  # (V, 3) uint8 RGB of mesh.vertices

    @property
    def ok(self) -> bool:
        return not self.error and len(self.mesh.faces) > 0

    def world_mesh(self) -> trimesh.Trimesh:
        """The mesh in the world frame, with its vertex colours when it has them."""
        mesh = self.mesh.copy().apply_transform(self.T_world_object)
        if self.vertex_colours is not None and len(self.vertex_colours) == len(mesh.vertices):
            mesh.visual.vertex_colors = np.column_stack([self.vertex_colours, np.full(len(mesh.vertices), 255)])
        return mesh

    def world_convex_parts(self) -> list[trimesh.Trimesh]:
        return [p.copy().apply_transform(self.T_world_object) for p in self.convex_parts]


@dataclass(frozen=True)
class ReconstructionSettings:
    """method: one of network.METHODS; checkpoint_path '' = the shipped checkpoint of the method's
    network variant; resolution 0 = the checkpoint's; device 'cpu', 'cuda' or 'auto'; k: grid side
    over object diameter, 0 = the checkpoint's (the k of its training data); threshold: occupancy
    probability of a solid voxel; table_height_m None = estimated per object; snap_to_depth: the
    seen part of each surface placed on the observed depth (surface_snapping), with snap settings
    `snap`; complete_revolutions: an object whose seen points lie on an upright solid of revolution
    that agrees with the view becomes that solid (revolution); complete_cuboids: else, one whose
    seen points lie on an upright cuboid that agrees with the view becomes that cuboid (cuboid)."""

    method: str = setting("arm", "Reconstruction method", choices=sorted(METHODS), parameter=True)
    checkpoint_path: str = setting("", "Checkpoint file ('': the method's shipped checkpoint)", parameter=True)
    device: str = setting("cpu", "Torch device", choices=("cpu", "cuda", "auto"), parameter=True)
    resolution: int = setting(0, "Voxels per grid side (0: the checkpoint's)", 0, 256)
    k: float = setting(0.0, "Grid side over the object's observed diameter (0: the checkpoint's)", 0.0, 16.0)
    threshold: float = setting(DEFAULT_THRESHOLD, "Occupancy probability of a solid voxel", 0.01, 0.99, parameter=True)
    min_component_voxels: int = setting(
        DEFAULT_MIN_COMPONENT_VOXELS, "Drop occupied components smaller than this, voxels", 1, 4096
    )
    smoothing_iterations: int = setting(
        DEFAULT_SMOOTHING_ITERATIONS, "Taubin smoothing iterations of each mesh", 0, 100
    )
    stable_base_tilt_deg: float = setting(
        DEFAULT_STABLE_BASE_TILT_DEG, "A base, where unseen, for objects toppling at this tilt, deg (0: off)", 0.0, 45.0
    )
    join_parts: bool = setting(True, "Join an object's separate parts where the view allows (connectivity)")
    snap_to_depth: bool = setting(True, "Place the seen part of each surface on the observed depth")
    snap: SnapSettings = field(default_factory=SnapSettings)
    complete_revolutions: bool = setting(True, "Complete upright solids of revolution from their seen side wall")
    revolution: RevolutionSettings = field(default_factory=RevolutionSettings)
    complete_cuboids: bool = setting(True, "Complete upright boxes from their seen faces, on the support or a box")
    cuboid: CuboidSettings = field(default_factory=CuboidSettings)
    remove_intersections: bool = setting(True, "Cut overlaps from the larger of two meshes (paper)")
    decomposition: DecompositionSettings = field(default_factory=DecompositionSettings)
    estimate_visibility: bool = setting(True, "Estimate each object's visible fraction")
    table_height_m: float | None = None
    batch_size: int = 16
    keep_probabilities: bool = False

    def __post_init__(self):
        object.__setattr__(self, "method", canonical_method(self.method))
        if not 0.0 < float(self.threshold) < 1.0:
            raise ValueError(f"threshold must be in (0, 1), got {self.threshold}")
        if int(self.resolution) < 0 or int(self.resolution) % 8:
            raise ValueError(f"resolution must be 0 (from the checkpoint) or a multiple of 8, got {self.resolution}")
        if not np.isfinite(self.k) or (self.k != 0 and self.k <= 1):
            raise ValueError(f"k must be 0 (from the checkpoint) or > 1, got {self.k}")
        if int(self.batch_size) < 1:
            raise ValueError(f"batch_size must be >= 1, got {self.batch_size}")

    @property
    def variant(self) -> str:
        return METHODS[self.method][0]

    @property
    def postprocess(self) -> str | None:
        return METHODS[self.method][1]


def resolve_checkpoint_path(settings: ReconstructionSettings) -> pathlib.Path:
    return (
        pathlib.Path(settings.checkpoint_path)
        if settings.checkpoint_path
        else default_checkpoint_path(settings.variant)
    )


def _empty_object(object_id: int, method: str, reason: str, frame: GridFrame | None = None) -> ReconstructedObject:
    return ReconstructedObject(int(object_id), np.eye(4), empty_mesh(), [], -1.0, frame, method, reason)


def _object_pose(mesh: trimesh.Trimesh) -> np.ndarray:
    centre = mesh.center_mass if mesh.is_watertight and mesh.volume > 0 else mesh.vertices.mean(0)
    T = np.eye(4)
    T[:3, 3] = centre
    return T


def estimate_visible_fraction(parts_world, labels, object_id, K, T_world_camera) -> float:
    """Visible pixels of the object over the pixels its reconstruction (convex parts, (N, 3) world vertex
    arrays) covers alone (clipped to 1; -1 when it projects to no pixel)."""
    height, width = labels.shape
    alone = silhouette(parts_world, K, T_world_camera, width, height).sum()
    if alone == 0:
        return -1.0
    return float(min(1.0, np.count_nonzero(labels == object_id) / alone))


class Reconstructor:
    """Holds the network and the caches; call it once per frame."""

    # Checked between stages and between objects' convex decompositions: True abandons the frame
    # (ReconstructionPreempted), e.g. so that a planner that just got a goal has the CPU.
    should_stop: Callable[[], bool] | None = None

    def __init__(self, settings: ReconstructionSettings | None = None, model: torch.nn.Module | None = None):
        self.settings = settings or ReconstructionSettings()
        self.device = resolve_device(self.settings.device)
        if model is None:
            path = resolve_checkpoint_path(self.settings)
            if not path.is_file():
                raise CheckpointError(
                    f"no checkpoint for method '{self.settings.method}' at {path}: train one with the "
                    f"'train' entry point or pass checkpoint_path"
                )
            model, config = load_checkpoint(
                path,
                self.device,
                expected_variant=self.settings.variant,
                expected_resolution=self.settings.resolution or None,
            )
            self.checkpoint_config = config
        else:
            if getattr(model, "variant", self.settings.variant) != self.settings.variant:
                raise CheckpointError(f"model variant {model.variant!r} does not fit method {self.settings.method!r}")
            self.checkpoint_config = {"variant": self.settings.variant, "resolution": getattr(model, "resolution", 0)}
        self.model = prepare_for_inference(model, self.device)
        self.resolution = int(self.settings.resolution or getattr(model, "resolution", 32))
        if getattr(model, "resolution", self.resolution) != self.resolution:
            raise CheckpointError(f"model resolution {model.resolution} differs from requested {self.resolution}")
        self.k = float(self.settings.k or getattr(model, "grid_k", CHECKPOINT_DEFAULT_K))  # load_checkpoint sets it
        self.decomposer = ConvexDecomposer(self.settings.decomposition)
        self.timer = StageTimer()

    def _stop_if_asked(self) -> None:
        if self.should_stop is not None and self.should_stop():
            raise ReconstructionPreempted("frame abandoned between stages")

    @property
    def last_timings_s(self) -> dict[str, float]:
        """Wall-clock seconds per stage of the last frame."""
        return self.timer.wall_s

    @property
    def last_cpu_s(self) -> dict[str, float]:
        """Process CPU seconds (all threads) per stage of the last frame."""
        return self.timer.cpu_s

    def __call__(self, rgb, depth_m, K, T_world_camera, labels, object_ids=None) -> list[ReconstructedObject]:
        """Objects of one frame, ascending id. Raises FrameInputError for a malformed frame (shapes,
        non-finite pose or intrinsics; GridInputError, a subclass, for the rgb or grid settings);
        objects that cannot be reconstructed come back empty with their error set."""
        if rgb is not None and np.asarray(rgb).shape[:2] != np.asarray(depth_m).shape[:2]:
            raise GridInputError(f"rgb shape {np.asarray(rgb).shape} does not match depth {np.asarray(depth_m).shape}")
        self.timer.reset()
        # every stage sees the same checked depth (non-finite values and speckles gone)
        frame = validate_frame(depth_m, K, T_world_camera, rgb=rgb, labels=labels)
        grids = self.grids(frame.depth_m, frame.K, frame.T_world_camera, frame.labels, object_ids)
        self._stop_if_asked()
        probabilities = self.predict(grids)
        objects = self.build_objects(grids, probabilities, frame.depth_m, frame.labels, frame.K, frame.T_world_camera)
        if rgb is not None:
            for obj in objects:
                if obj.ok:
                    vertices = obj.mesh.vertices @ obj.T_world_object[:3, :3].T + obj.T_world_object[:3, 3]
                    obj.vertex_colours = vertex_colours(
                        vertices, frame.rgb, frame.depth_m, frame.labels, obj.id, frame.K, frame.T_world_camera
                    )
        return objects

    def grids(self, depth_m, K, T_world_camera, labels, object_ids=None) -> FrameGrids:
        s = self.settings
        with self.timer("grid"):
            return frame_grids(
                depth_m, K, T_world_camera, labels, object_ids, self.resolution, self.k, s.table_height_m
            )

    def predict(self, grids: FrameGrids) -> np.ndarray:
        """Occupancy probabilities [N, d, d, d] of the frame's grids, after the method's post-processing
        (ray carving: observed-empty voxels cleared; extrusion: columns filled down to the table)."""
        with self.timer("network"):
            probabilities = predict_occupancy(self.model, grids.grids, self.device, self.settings.batch_size)
        with self.timer("postprocess"):
            if self.settings.postprocess == "ray_carving":
                probabilities = np.stack([ray_carve(p, g) for p, g in zip(probabilities, grids.grids, strict=True)])
            elif self.settings.postprocess == "extrude":
                probabilities = extrude_to_table(probabilities.transpose(1, 2, 3, 0)).transpose(3, 0, 1, 2)
        return probabilities

    def build_objects(
        self, grids: FrameGrids, probabilities: np.ndarray, depth_m, labels, K, T_world_camera
    ) -> list[ReconstructedObject]:
        """Meshes, intersection removal, convex parts and visibility for per-object occupancy
        probabilities [N, d, d, d] laid out in grids.frames (the stages after the network)."""
        s = self.settings
        labels = np.asarray(labels)
        self._stop_if_asked()
        with self.timer("meshing"):
            # What was seen of an object is part of it: observed voxels (F1) the network missed are
            # added. Where it predicted nothing (a sliver of an object, mostly), the observed voxels
            # alone stand in, all of their components kept.
            from_observed = [
                not (p > s.threshold).any() and bool(g[0].any())
                for p, g in zip(probabilities, grids.grids, strict=True)
            ]
            meshes = [
                occupancy_mesh(
                    add_missed_observed_voxels(p, s.threshold, g[0]),
                    frame,
                    s.threshold,
                    1 if alone else s.min_component_voxels,
                    grid=g,
                    smoothing_iterations=s.smoothing_iterations,
                    stable_base_tilt_deg=s.stable_base_tilt_deg,
                    join_parts=s.join_parts,
                )
                for p, frame, g, alone in zip(probabilities, grids.frames, grids.grids, from_observed, strict=True)
            ]
        K = np.asarray(K, dtype=np.float64)
        T_world_camera = np.asarray(T_world_camera, dtype=np.float64)
        completed = [False] * len(meshes)
        if (s.complete_revolutions or s.complete_cuboids) and grids.observation is not None:
            with self.timer("shapes"):
                meshes, completed = self.complete_shapes(meshes, grids)
        if s.snap_to_depth and meshes:
            with self.timer("snapping"):
                snapped = self.snap_meshes(meshes, grids, depth_m, labels, K, T_world_camera)
                meshes = [m if done else n for m, n, done in zip(meshes, snapped, completed, strict=True)]
        self._stop_if_asked()
        with self.timer("intersections"):
            if s.remove_intersections and len(meshes) > 1:
                meshes, _ = remove_intersections(meshes)

        objects = {i: _empty_object(i, s.method, reason) for i, reason in grids.errors.items()}
        for n, (object_id, frame, mesh) in enumerate(zip(grids.object_ids, grids.frames, meshes, strict=True)):
            if len(mesh.faces) == 0:
                reason = f"no voxel above threshold {s.threshold} for object {object_id}"
                objects[object_id] = _empty_object(object_id, s.method, reason, frame)
                continue
            self._stop_if_asked()
            T_world_object = _object_pose(mesh)
            local = mesh.copy().apply_translation(-T_world_object[:3, 3])
            with self.timer("decomposition"):
                parts = self.decomposer(local)
            visible = -1.0
            if s.estimate_visibility:
                with self.timer("visibility"):
                    parts_world = [p.vertices + T_world_object[:3, 3] for p in parts] or [mesh.vertices]
                    visible = estimate_visible_fraction(parts_world, labels, object_id, K, T_world_camera)
            kept = probabilities[n] if s.keep_probabilities else None
            objects[object_id] = ReconstructedObject(
                object_id, T_world_object, local, parts, visible, frame, s.method, "", kept, from_observed[n]
            )
        return [objects[i] for i in sorted(objects)]

    def complete_shapes(self, meshes, grids: FrameGrids) -> tuple[list[trimesh.Trimesh], list[bool]]:
        """Each non-empty mesh replaced by its object's solid of revolution (revolution_completion) or,
        failing that, its upright cuboid (cuboid_completion) where one fits the view -> (meshes,
        replaced per mesh). Objects go lowest first, so a box stacked on a box rests on its cuboid."""
        s, observation = self.settings, grids.observation
        out, replaced = list(meshes), [False] * len(meshes)
        points = [observation.points_of(i) for i in grids.object_ids]
        order = sorted(range(len(meshes)), key=lambda n: float(points[n][:, 2].min()) if len(points[n]) else 0.0)
        for n in order:
            if not len(out[n].faces):
                continue
            object_id, frame, grid = grids.object_ids[n], grids.frames[n], grids.grids[n]
            normals = observation.normals_of(object_id)
            solid = None
            if s.complete_revolutions:
                solid = revolution_completion(points[n], normals, frame, grid, s.revolution)
            if solid is None and s.complete_cuboids:
                others = out[:n] + out[n + 1 :]
                hidden = functools.partial(observation.hidden_by_others, object_id=object_id)
                solid = cuboid_completion(points[n], normals, frame, grid, others, hidden, s.cuboid)
            if solid is not None:
                out[n], replaced[n] = solid, True
        return out, replaced

    def snap_meshes(self, meshes, grids: FrameGrids, depth_m, labels, K, T_world_camera) -> list[trimesh.Trimesh]:
        """Each mesh's seen vertices moved onto the object's observed depth (surface_snapping), by at
        most snap.max_shift_voxels of its grid's voxels."""
        snap = self.settings.snap
        object_depth = smoothed_object_depth(depth_m, labels, grids.object_ids, snap)
        return [
            snap_to_observed_depth(
                mesh,
                object_depth,
                labels,
                object_id,
                K,
                T_world_camera,
                snap.max_shift_voxels * frame.voxel_size_m,
                frame.table_height_m,
                snap,
            )[0]
            for mesh, object_id, frame in zip(meshes, grids.object_ids, grids.frames, strict=True)
        ]


_RECONSTRUCTORS: dict[ReconstructionSettings, Reconstructor] = {}


def reconstruct(rgb, depth_m, K, T_world_camera, labels, method: str = "arm", **settings) -> list[ReconstructedObject]:
    """One-call API: reconstruct(rgb, depth_m, K, T_world_camera, labels, method='arm', checkpoint_path='',
    device='cpu', threshold=0.5, ...) -> list[ReconstructedObject]. Keyword settings are those of
    ReconstructionSettings (decomposition takes a DecompositionSettings). The network is loaded once
    per distinct settings and reused."""
    key = ReconstructionSettings(method=method, **settings)
    reconstructor = _RECONSTRUCTORS.get(key)
    if reconstructor is None:
        reconstructor = Reconstructor(key)
        _RECONSTRUCTORS[key] = reconstructor
    return reconstructor(rgb, depth_m, K, T_world_camera, labels)
