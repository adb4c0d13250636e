"""bench_recon's settings, method names and targets."""

from __future__ import annotations

import dataclasses
import pathlib

from arm_benchmarks.methods import GROUND_TRUTH
from arm_benchmarks.run_key import run_key
from arm_reconstruction.meshing import DEFAULT_SMOOTHING_ITERATIONS, DEFAULT_STABLE_BASE_TILT_DEG, DEFAULT_THRESHOLD
from arm_reconstruction.metrics import DEFAULT_CHAMFER_SAMPLES, DEFAULT_IOU_RESOLUTION
from arm_sim.appearance import DEFAULT_DOMAIN

VISIBLE_ONLY = "visible-only"
NETWORK_METHODS = ("baseline", "baseline+ray-carving", "baseline+E", "arm-c-s", "arm-c", "arm")
ALL_METHODS = (VISIBLE_ONLY, *NETWORK_METHODS, GROUND_TRUTH)
VISIBILITY_BINS = ((0.0, 0.2), (0.2, 0.4), (0.4, 0.6), (0.6, 0.8), (0.8, 1.0))
MAX_VIEW_TRIES = 20
MIN_MATCH_IOU = 0.5
OCCLUDED_VISIBILITY = 0.6
QUALITATIVE_PER_SCENE = 2
QUALITATIVE_MAX_VISIBILITY = 0.5
TARGET_CHAMFER_REDUCTION = 0.28
TARGET_STABLE_FRACTION = 0.9
TARGET_STABLE_GAP = 0.03
TARGET_ARM_CHAMFER_M = 0.005
TARGET_ARM_CHAMFER_VISIBLE_M = 0.004  # visible fraction 0.8-1.0
TARGET_ARM_IOU = 0.5
TARGET_NORMAL_CONSISTENCY = 0.85
TARGET_RUNTIME_S = 900.0
# Every package whose code changes a per-scene result (the renderer, the segmentation, the pipeline,
# the twin's convex parts, this benchmark's scoring).
RESULT_PACKAGES = ("arm_core", "arm_sim", "arm_segmentation", "arm_reconstruction", "arm_planner", "arm_benchmarks")


# BenchConfig fields passed to every method's ReconstructionSettings
PIPELINE_FIELDS = (
    "threshold",
    "smoothing_iterations",
    "snap_to_depth",
    "stable_base_tilt_deg",
    "join_parts",
    "complete_cuboids",
)


@dataclasses.dataclass(frozen=True)
class BenchConfig:
    scenes: int = 36
    seed: int = 0
    objects: str = ""
    segmentation: str = GROUND_TRUTH
    out: str = "results/recon"
    methods: tuple = ALL_METHODS
    checkpoint_dir: str = ""
    min_objects: int = 3
    max_objects: int = 20
    min_visible_pixels: int = 50
    chamfer_samples: int = DEFAULT_CHAMFER_SAMPLES
    iou_resolution: int = DEFAULT_IOU_RESOLUTION
    settle_s: float = 5.0
    physics_timestep_s: float = 0.01
    stable_threshold_m: float = 0.01
    depth_noise: bool = True
    domain: str = DEFAULT_DOMAIN
    threshold: float = DEFAULT_THRESHOLD
    smoothing_iterations: int = DEFAULT_SMOOTHING_ITERATIONS
    snap_to_depth: bool = True
    stable_base_tilt_deg: float = DEFAULT_STABLE_BASE_TILT_DEG
    join_parts: bool = True
    complete_cuboids: bool = True
    view: str = "occluded"
    view_candidates: int = 8
    qualitative: int = 4
    threads: int = 2

    def pipeline(self) -> dict:
        """The ReconstructionSettings fields every method's meshes share in this run."""
        return {name: getattr(self, name) for name in PIPELINE_FIELDS}

    def result_key(self, checkpoint_paths) -> str:
        """Run key of the per-scene results: the settings that change them (not scenes, out, qualitative,
        threads, methods, checkpoint_dir), the checkpoints' bytes and RESULT_PACKAGES' source."""
        fields = dataclasses.asdict(self)
        for name in ("scenes", "out", "qualitative", "threads", "methods", "checkpoint_dir"):
            fields.pop(name)
        fields["objects"] = str(pathlib.Path(self.objects).resolve()) if self.objects else "heldout"
        return run_key(fields, sorted(checkpoint_paths), RESULT_PACKAGES)
