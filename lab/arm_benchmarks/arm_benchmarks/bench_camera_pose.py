"""bench_camera_pose: T_world_camera estimated from depth alone (no calibrated camera pose).

Seeded cluttered scenes (held-out objects, settled by physics) are rendered with the simulator's
depth noise at camera poses sampled as in the paper's benchmark (arm_sim.views.BenchmarkScene,
several views per scene); arm_segmentation.camera_pose_estimate sees only the depth image and K.
Per frame: the gravity error (angle between the estimated and the true world-up) and the table-height
error (estimated camera height above the table minus the true one). A frame without an estimate
counts as a miss. Writes OUT/summary.json (percentiles, share of frames within 1 degree and 5 mm,
target >= 95 %) and OUT/errors.png (histograms).
"""

import argparse
import json
import os
import pathlib
import time

import matplotlib
import numpy as np
from tqdm import tqdm

from arm_benchmarks.machine import machine_description
from arm_segmentation.camera_pose_estimate import CameraPoseError, estimate_camera_pose
from arm_sim.appearance import DEFAULT_DOMAIN, DOMAINS
from arm_sim.objects import object_pool
from arm_sim.views import BenchmarkScene

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

GRAVITY_TOLERANCE_DEG = 1.0
HEIGHT_TOLERANCE_M = 0.005
TARGET_SHARE = 0.95


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=100, help="number of rendered frames")
    parser.add_argument("--views-per-scene", type=int, default=4, help="camera poses rendered per scene")
    parser.add_argument("--seed", type=int, default=0, help="base seed of the scenes and camera poses")
    parser.add_argument("--min-objects", type=int, default=3)
    parser.add_argument("--max-objects", type=int, default=20)
    parser.add_argument("--no-noise", action="store_true", help="render perfect depth")
    parser.add_argument(
        "--domain", choices=DOMAINS, default=DEFAULT_DOMAIN, help="visual domain of the rendered scenes"
    )
    parser.add_argument("--out", default=None, help="output folder (default results/camera_pose[_seedN])")
    args = parser.parse_args(argv)
    if args.frames < 1 or args.views_per_scene < 1 or not 1 <= args.min_objects <= args.max_objects:
        parser.error("need --frames >= 1, --views-per-scene >= 1 and 1 <= --min-objects <= --max-objects")
    if args.out is None:
        args.out = "results/camera_pose" + (f"_seed{args.seed}" if args.seed else "")
    return args


def frame_errors(depth_m: np.ndarray, K: np.ndarray, T_true: np.ndarray, table_height_m: float) -> dict:
    """Gravity error (deg) and camera-height error (m) of one estimate, or the reason it failed."""
    start = time.perf_counter()
    try:
        estimate = estimate_camera_pose(depth_m, K)
    except CameraPoseError as error:
        return {"error": str(error)}
    up_estimate, up_true = estimate.T_world_camera[2, :3], T_true[2, :3]
    return {
        "gravity_error_deg": float(np.degrees(np.arccos(np.clip(up_estimate @ up_true, -1.0, 1.0)))),
        "height_error_m": float(estimate.T_world_camera[2, 3] - (T_true[2, 3] - table_height_m)),
        "camera_height_m": float(T_true[2, 3] - table_height_m),
        "camera_distance_m": float(np.linalg.norm(T_true[:3, 3] - [0.0, 0.0, table_height_m])),
        "inlier_fraction": estimate.inlier_fraction,
        "estimate_ms": 1e3 * (time.perf_counter() - start),
    }


def run_scene(index: int, args, pool) -> list[dict]:
    rng = np.random.default_rng([args.seed, index])
    objects = (args.min_objects, args.max_objects)
    rows = []
    options = {"depth_noise": not args.no_noise, "with_visibility": False, "domain": args.domain}
    with BenchmarkScene(pool, rng, objects, **options) as views:
        for view in range(args.views_per_scene):
            frame = views.render()
            errors = frame_errors(frame.depth_m, frame.K, frame.T_world_camera, views.scene.table_height_m)
            rows.append({"scene": index, "view": view, "n_objects": len(views.scene.objects), **errors})
    return rows


def percentiles(values) -> dict:
    return {f"p{q}": float(np.percentile(values, q)) for q in (50, 90, 95, 99)} | {"max": float(np.max(values))}


def summarize(rows: list[dict], args) -> dict:
    ok = [r for r in rows if "error" not in r]
    gravity = np.array([r["gravity_error_deg"] for r in ok])
    height = np.abs([r["height_error_m"] for r in ok])
    within = sum(
        1 for g, h in zip(gravity, height, strict=True) if g <= GRAVITY_TOLERANCE_DEG and h <= HEIGHT_TOLERANCE_M
    )
    share = within / len(rows)
    return {
        "frames": len(rows),
        "estimated": len(ok),
        "failures": [{"scene": r["scene"], "view": r["view"], "error": r["error"]} for r in rows if "error" in r],
        "gravity_error_deg": percentiles(gravity) if ok else {},
        "abs_height_error_m": percentiles(height) if ok else {},
        "share_within_1deg": float(np.sum(gravity <= GRAVITY_TOLERANCE_DEG) / len(rows)),
        "share_within_5mm": float(np.sum(height <= HEIGHT_TOLERANCE_M) / len(rows)),
        "share_within_1deg_and_5mm": share,
        "target_share": TARGET_SHARE,
        "target_met": share >= TARGET_SHARE,
        "estimate_ms_median": float(np.median([r["estimate_ms"] for r in ok])) if ok else float("nan"),
        "seed": args.seed,
        "views_per_scene": args.views_per_scene,
        "objects_per_scene": [args.min_objects, args.max_objects],
        "depth_noise": not args.no_noise,
        "domain": args.domain,
        "machine": machine_description(),
        "cpu_count": os.cpu_count(),
        "measured_at": time.strftime("%Y-%m-%dT%H:%M:%S"),
    }


def write_histograms(path: pathlib.Path, rows: list[dict], seed: int) -> None:
    ok = [r for r in rows if "error" not in r]
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    gravity = [r["gravity_error_deg"] for r in ok]
    height_mm = [1e3 * r["height_error_m"] for r in ok]
    axes[0].hist(gravity, bins=40, color="tab:blue")
    axes[0].axvline(GRAVITY_TOLERANCE_DEG, color="k", linestyle="--", label="1 deg")
    axes[0].set_xlabel("gravity error (deg)")
    axes[1].hist(height_mm, bins=40, color="tab:orange")
    for x in (-1e3 * HEIGHT_TOLERANCE_M, 1e3 * HEIGHT_TOLERANCE_M):
        axes[1].axvline(x, color="k", linestyle="--")
    axes[1].set_xlabel("table-height error (mm, estimate - truth)")
    for ax in axes:
        ax.set_ylabel("frames")
    axes[0].legend()
    fig.suptitle(f"camera pose from depth: {len(ok)}/{len(rows)} frames estimated (seed {seed})")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv=None) -> int:
    args = parse_args(argv)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    pool = object_pool(split="heldout", seed=args.seed)
    rows = []
    n_scenes = -(-args.frames // args.views_per_scene)
    for index in tqdm(range(n_scenes), desc="bench_camera_pose", unit="scene"):
        rows += run_scene(index, args, pool)
    rows = rows[: args.frames]
    summary = summarize(rows, args)
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    (out / "frames.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    write_histograms(out / "errors.png", rows, args.seed)
    print(
        f"{summary['estimated']}/{summary['frames']} estimated; within 1 deg and 5 mm: "
        f"{summary['share_within_1deg_and_5mm']:.1%} (target {TARGET_SHARE:.0%}); gravity p95 "
        f"{summary['gravity_error_deg'].get('p95', float('nan')):.3f} deg, |height| p95 "
        f"{1e3 * summary['abs_height_error_m'].get('p95', float('nan')):.2f} mm -> {out}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
