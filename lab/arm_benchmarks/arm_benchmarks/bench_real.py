"""bench_real: the offline pipeline on folders of real RGB-D frames (the reconstruct_frames layout).

    bench_real DIR [DIR ...] [--out results/real] [--noise-copies 5] [--physics-s 2]

Each frame goes through reconstruct_frames' own code path (FrameReconstructor: the package's camera-pose
estimate unless DIR/poses.json gives one, segmentation, reconstruction, the MJCF scene). Per frame and
per set it reports:
- the support found: camera height above it (m), its normal in the camera frame, the share of the
  valid depth pixels on it, and whether the reconstructed objects rest on it (or on an object);
- instances returned and the time per frame (whole command, and the segmentation alone);
- the share of the instances' pixels with depth that lie on the support (within 5 mm of it): the
  table beside an object taken for the object, measurable without labels;
- the scene's stable fraction: the frame's scene.xml after physics_s of gravity; an object is stable
  when it moved < 2 cm and turned < 15 degrees;
- with DIR/labels/<frame>.png: the UOIS metrics (overlap / boundary F, F@75, instances per object,
  background false positives), averaged per image;
- stability under sensor noise: the depth re-encoded noise_copies times (the simulator's depth-noise
  model plus +-1 mm quantisation); the largest change of the support (degrees, metres) and of the
  instance count against the frame as given;
- the frame as other cameras would give it (arm_benchmarks.real.camera_variants: a 1.7x longer lens,
  twice and half the resolution, speckled depth; off with --no-camera-variants): support found and
  the instance count against the frame's own instances still in view, and the UOIS metrics where
  labelled.
Writes OUT/summary.json, OUT/report.md, OUT/<set>/sheets/<frame>.png (overlay | scene from the camera
after the physics | from the side) and the frames' reconstruct_frames outputs under OUT/<set>/frames/.
A frame whose bench.json exists is not redone (resume), unless --overwrite.
"""

import argparse
import json
import pathlib
import sys
import time
from dataclasses import replace

import cv2
import mujoco
import numpy as np
from tqdm import tqdm

from arm_benchmarks.machine import machine_description
from arm_benchmarks.real.camera_variants import camera_variants, kept_instances
from arm_benchmarks.real.scene_physics import (
    STABLE_MOVE_M,
    STABLE_TURN_DEG,
    render_views,
    settle_scene,
    side_view_pose,
)
from arm_benchmarks.stats import json_safe, mean, median, percentile
from arm_core.atomic_io import atomic_write, atomic_write_json
from arm_core.camera import world_height
from arm_offline.inputs import POSES_FILE, find_frames, find_intrinsics, load_camera, load_frame, load_poses
from arm_offline.reconstruct_frames import SCENE_FILE, FrameReconstructor, OfflineSettings, camera_pose
from arm_reconstruction.pipeline import Reconstructor
from arm_segmentation.camera_pose_estimate import CameraPoseError
from arm_segmentation.metrics import segmentation_metrics
from arm_segmentation.segmentation import segment_detailed
from arm_sim.depth_noise import DepthNoise, apply_depth_noise

LABELS_DIR = "labels"
METRIC_KEYS = (
    "overlap_f",
    "boundary_f",
    "f_at_75",
    "instances_per_object",
    "background_fp_fraction",
)
NOISE_TARGET_DEG, NOISE_TARGET_M, NOISE_TARGET_INSTANCES = 1.0, 0.005, 1
ON_SUPPORT_M = 0.005  # an instance pixel this near the support plane lies on it
BENCH_FILE = "bench.json"
SHEET_WIDTH_PX = 480


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folders", nargs="+", type=pathlib.Path, help="frame folders (reconstruct_frames layout)")
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("results/real"))
    parser.add_argument("--noise-copies", type=int, default=5, help="noisy re-encodings of each frame's depth")
    parser.add_argument("--physics-s", type=float, default=2.0, help="seconds of gravity on each scene")
    parser.add_argument("--max-frames", type=int, default=0, help="first N frames of each folder (0: all)")
    parser.add_argument("--depth-scale", type=float, default=0.001, help="metres per depth unit")
    parser.add_argument("--seed", type=int, default=0, help="seed of the depth noise")
    parser.add_argument(
        "--no-camera-variants", action="store_true", help="skip the frames as other cameras would give them"
    )
    parser.add_argument("--overwrite", action="store_true", help="redo frames already benchmarked")
    args = parser.parse_args(argv)
    for folder in args.folders:
        if not folder.is_dir():
            parser.error(f"{folder} is not a folder")
    if args.noise_copies < 0 or args.physics_s <= 0 or args.max_frames < 0:
        parser.error("need --noise-copies >= 0, --physics-s > 0 and --max-frames >= 0")
    return args


def perturbed_depth(depth_m: np.ndarray, K: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The depth as a second read-out of the sensor would give it: the simulator's noise model (axial
    noise, disparity quantisation, drop-outs at edges) without its range cut, then +-1 mm of
    re-quantisation to whole millimetres."""
    noisy = apply_depth_noise(depth_m, K, rng, DepthNoise(min_range_m=0.0, max_range_m=np.inf))
    requantised = np.round(noisy * 1000.0 + rng.uniform(-1.0, 1.0, noisy.shape)) / 1000.0
    return np.where(noisy > 0, requantised, 0.0).astype(np.float32)  # no return stays no return


def support_fields(T_world_camera: np.ndarray) -> dict:
    """Camera height above the support (m), the support's normal in the camera frame, and how far
    the optical axis looks down (degrees below the support plane)."""
    up_camera = T_world_camera[2, :3]
    return {
        "camera_height_m": float(T_world_camera[2, 3]),
        "normal_camera": [round(float(v), 5) for v in up_camera],
        "look_down_deg": float(np.degrees(np.arcsin(np.clip(-up_camera[2], -1.0, 1.0)))),
    }


def noise_stability(rgb, depth_m, K, T_world_camera, n_instances: int, processor, copies: int, rng) -> dict:
    """Largest change of the support and of the instance count over noisy copies of the depth."""
    gravity, height, count, errors = [], [], [], []
    for _ in range(copies):
        noisy = perturbed_depth(depth_m, K, rng)
        try:
            T, _ = camera_pose(noisy, K, None)
        except CameraPoseError as error:
            errors.append(str(error))
            continue
        labels = segment_detailed(rgb, noisy, K, T, processor.settings.segmentation).labels
        up, up_given = T[2, :3], T_world_camera[2, :3]
        gravity.append(float(np.degrees(np.arctan2(np.linalg.norm(np.cross(up, up_given)), up @ up_given))))
        height.append(abs(float(T[2, 3] - T_world_camera[2, 3])))
        count.append(abs(len(np.unique(labels[labels > 0])) - n_instances))
    worst = {
        "copies": copies,
        "failed": len(errors),
        "errors": errors,
        "max_gravity_change_deg": max(gravity, default=None),
        "max_height_change_m": max(height, default=None),
        "max_instance_change": max(count, default=None),
    }
    worst["held"] = bool(
        not errors
        and copies > 0
        and worst["max_gravity_change_deg"] < NOISE_TARGET_DEG
        and worst["max_height_change_m"] < NOISE_TARGET_M
        and worst["max_instance_change"] <= NOISE_TARGET_INSTANCES
    )
    return worst


def on_support_share(labels: np.ndarray, depth_m: np.ndarray, K: np.ndarray, T_world_camera: np.ndarray):
    """Share of the instances' pixels with depth within ON_SUPPORT_M of the support plane (world z = 0),
    or None without such pixels. An object's base adds a thin line; the table beside it, more."""
    seen = (labels > 0) & (depth_m > 0)
    if not np.any(seen):
        return None
    height = world_height(depth_m, K, T_world_camera)
    return float(np.mean(np.abs(height[seen]) < ON_SUPPORT_M))


def contact_sheet(overlay_rgb: np.ndarray, views: list[np.ndarray], titles: list[str]) -> np.ndarray:
    """One row: each image scaled to SHEET_WIDTH_PX wide with its title written on it (RGB)."""
    tiles = []
    for image, title in zip([overlay_rgb, *views], titles, strict=True):
        scale = SHEET_WIDTH_PX / image.shape[1]
        tile = cv2.resize(image, (SHEET_WIDTH_PX, int(round(image.shape[0] * scale))), interpolation=cv2.INTER_AREA)
        cv2.putText(tile, title, (8, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 2, cv2.LINE_AA)
        tiles.append(tile)
    height = max(t.shape[0] for t in tiles)
    return np.hstack([np.pad(t, ((0, height - t.shape[0]), (0, 0), (0, 0))) for t in tiles])


def variant_checks(rgb, depth_m, K, truth, predicted, processor, rng) -> list[dict]:
    """The segmentation on each camera variant of the frame (real.camera_variants): support found,
    instances against the reference (the frame's own instances that stay in view), and with truth
    labels the UOIS metrics; held when a support is found and the count is within one of the reference."""
    labels = [predicted] if truth is None else [predicted, truth]
    rows = []
    for variant in camera_variants(rgb, depth_m, K, labels, rng):
        scale_px = variant.depth_m.size / depth_m.size
        row = {"variant": variant.name, "reference": kept_instances(predicted, variant.labels[0], scale_px)}
        try:
            T, _ = camera_pose(variant.depth_m, variant.K, None)
        except CameraPoseError as error:
            rows.append(row | {"support_found": False, "instances": 0, "held": False, "empty_reason": str(error)})
            continue
        result = segment_detailed(variant.rgb, variant.depth_m, variant.K, T, processor.settings.segmentation)
        count = len(np.unique(result.labels[result.labels > 0]))
        row |= {"support_found": True, "instances": count, "empty_reason": result.empty_reason}
        row["held"] = abs(count - row["reference"]) <= NOISE_TARGET_INSTANCES
        if truth is not None:
            metrics = segmentation_metrics(result.labels, variant.labels[1])
            row["metrics"] = {k: float(metrics[k]) for k in METRIC_KEYS}
        rows.append(row)
    return rows


def aggregate_variants(rows: list[dict]) -> dict:
    """Per camera variant over a set's frames: support found, frames with an instance in view that came
    back empty, held share, mean instance count change, and the mean UOIS metrics where labelled."""
    by_name: dict[str, list[dict]] = {}
    for r in rows:
        for v in r.get("variants", []):
            by_name.setdefault(v["variant"], []).append(v)
    out = {}
    for name, vs in by_name.items():
        labelled = [v["metrics"] for v in vs if "metrics" in v]
        out[name] = {
            "frames": len(vs),
            "support_found": sum(v["support_found"] for v in vs),
            "empty_with_objects": sum(v["instances"] == 0 and v["reference"] > 0 for v in vs),
            "held_fraction": mean([v["held"] for v in vs]),
            "mean_instance_change": mean([abs(v["instances"] - v["reference"]) for v in vs]),
        }
        if labelled:
            out[name]["metrics"] = {k: mean([m[k] for m in labelled]) for k in METRIC_KEYS}
    return out


def bench_frame(files, camera, pose, out_set: pathlib.Path, processor, args, rng) -> dict:
    """One frame through the offline command, its scene's physics, its labels and the noisy copies."""
    folder = out_set / "frames" / files.name
    entry = processor(files, camera, pose, folder)
    row = {
        "frame": files.name,
        "ok": entry["ok"],
        "error": entry["error"],
        "pose_source": entry.get("pose_source"),
        "inlier_fraction": entry.get("pose_inlier_fraction"),
        "instances": entry.get("n_segmented", 0),
        "empty_reason": entry.get("empty_reason", ""),
        "reconstructed": entry.get("n_reconstructed", 0),
        "time_s": entry["timings_s"].get("total"),
        "segmentation_s": entry["timings_s"].get("segmentation"),
        "support_found": "T_world_camera" in entry,
    }
    if row["support_found"]:
        T_world_camera = np.asarray(entry["T_world_camera"], dtype=np.float64)
        row |= support_fields(T_world_camera)
    if not entry["ok"]:
        return row
    model = mujoco.MjModel.from_xml_path(str(folder / SCENE_FILE))
    data, motions = settle_scene(model, args.physics_s)
    row["objects"] = [
        {
            "body": m.body,
            "moved_m": m.moved_m,
            "turned_deg": m.turned_deg,
            "stable": m.stable,
            "resting": m.resting,
            "bottom_above_table_m": m.bottom_above_table_m,
        }
        for m in motions
    ]
    row["stable"] = sum(m.stable for m in motions)
    row["resting"] = sum(m.resting for m in motions)
    rgb, depth_m = processor.undistorted(*load_frame(files, camera, args.depth_scale), camera)
    predicted = cv2.imread(str(folder / "labels.png"), cv2.IMREAD_UNCHANGED)
    row["on_support_share"] = on_support_share(predicted, depth_m, camera.K, T_world_camera)
    labels_path = files.colour[0].parent.parent / LABELS_DIR / f"{files.name}.png"
    truth = cv2.imread(str(labels_path), cv2.IMREAD_UNCHANGED) if labels_path.is_file() else None
    if truth is not None:
        metrics = segmentation_metrics(predicted, truth)
        row["metrics"] = {k: float(metrics[k]) for k in METRIC_KEYS} | {"n_gt": metrics["n_gt"]}
        if not np.any((truth > 0) & (depth_m <= 0)):
            # labels drawn only where the sensor returned depth (as OSD's): scored on those pixels too
            on_depth = segmentation_metrics(np.where(depth_m > 0, predicted, 0), truth)
            row["metrics_on_depth"] = {k: float(on_depth[k]) for k in METRIC_KEYS}
    row["noise"] = noise_stability(
        rgb, depth_m, camera.K, T_world_camera, row["instances"], processor, args.noise_copies, rng
    )
    if not args.no_camera_variants:
        row["variants"] = variant_checks(rgb, depth_m, camera.K, truth, predicted, processor, rng)
    centres = [data.xpos[model.body(m.body).id] for m in motions]
    target = np.mean(centres, axis=0) if centres else np.zeros(3)
    poses = [T_world_camera, side_view_pose(T_world_camera, target)]
    views = render_views(model, data, poses, camera.K, rgb.shape[1], rgb.shape[0])
    overlay_rgb = cv2.imread(str(folder / "overlay.png"))[..., ::-1]
    titles = [
        f"{files.name}: {row['instances']} instances",
        f"after {args.physics_s:g} s: {row['stable']}/{len(motions)} stable",
        "side view",
    ]
    sheet = contact_sheet(overlay_rgb, views, titles)
    sheet_path = out_set / "sheets" / f"{files.name}.png"
    sheet_path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(sheet_path, lambda tmp: cv2.imwrite(str(tmp), sheet[..., ::-1]))
    row["sheet"] = str(sheet_path.relative_to(args.out))
    return row


def aggregate(rows: list[dict]) -> dict:
    """Totals of one set (metrics averaged per image as in the UOIS papers)."""
    ok = [r for r in rows if r["ok"]]
    objects = [o for r in ok for o in r.get("objects", [])]
    noise = [r["noise"] for r in ok if "noise" in r and r["noise"]["copies"] > 0]
    labelled = [r["metrics"] for r in ok if "metrics" in r]
    on_depth = [r["metrics_on_depth"] for r in ok if "metrics_on_depth" in r]
    times = [r["time_s"] for r in ok if r["time_s"] is not None]
    seg_times = [r["segmentation_s"] for r in ok if r["segmentation_s"] is not None]
    out = {
        "frames": len(rows),
        "support_found": sum(r["support_found"] for r in rows),
        "failed_frames": {r["frame"]: r["error"] for r in rows if not r["ok"]},
        "empty_frames": {r["frame"]: r["empty_reason"] for r in ok if r["instances"] == 0},
        "instances": sum(r["instances"] for r in ok),
        "instances_per_frame": mean([r["instances"] for r in ok]),
        "objects_simulated": len(objects),
        "stable_fraction": mean([o["stable"] for o in objects]),
        "resting_fraction": mean([o["resting"] for o in objects]),
        "on_support_share": mean([r["on_support_share"] for r in ok if r.get("on_support_share") is not None]),
        "time_s_median": median(times),
        "time_s_p90": percentile(times, 90),
        "segmentation_s_median": median(seg_times),
        "inlier_fraction_median": median([r["inlier_fraction"] for r in ok if r["inlier_fraction"] is not None]),
    }
    if noise:
        out["noise"] = {
            "frames": len(noise),
            "held_fraction": mean([n["held"] for n in noise]),
            "max_gravity_change_deg": max((n["max_gravity_change_deg"] or 0.0) for n in noise),
            "max_height_change_m": max((n["max_height_change_m"] or 0.0) for n in noise),
            "max_instance_change": max((n["max_instance_change"] or 0) for n in noise),
            "failed_copies": sum(n["failed"] for n in noise),
        }
    if labelled:
        out["metrics"] = {k: mean([m[k] for m in labelled]) for k in METRIC_KEYS} | {"frames": len(labelled)}
    if on_depth:
        out["metrics_on_depth"] = {k: mean([m[k] for m in on_depth]) for k in METRIC_KEYS} | {"frames": len(on_depth)}
    variants = aggregate_variants(ok)
    if variants:
        out["camera_variants"] = variants
    return out


def _fmt(value, scale: float = 1.0, digits: int = 3) -> str:
    return "-" if value is None or not np.isfinite(value) else f"{value * scale:.{digits}f}"


def write_report(path: pathlib.Path, summary: dict) -> None:
    lines = [
        "# bench_real: the offline pipeline on real RGB-D frames",
        "",
        f"`{summary['command']}` on {summary['machine']}, {summary['measured_at']}. Pose: the package's own "
        "estimate unless a poses.json is given. Stable: moved < "
        f"{STABLE_MOVE_M * 100:g} cm and turned < {STABLE_TURN_DEG:g} deg after {summary['physics_s']:g} s of "
        "gravity on the frame's own scene.xml. Noise held: over the noisy copies, the support moved < 1 deg "
        "and < 5 mm and the instance count by at most one. On support: the share of the instances' pixels "
        f"with depth within {ON_SUPPORT_M * 1000:g} mm of the support (the table taken for an object).",
        "",
        "| set | frames | support found | empty | instances / frame | on support | stable | resting | noise held | "
        "time / frame (s) | segmentation (s) | overlap F | boundary F | F@75 | inst. / object | background FP |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, s in summary["sets"].items():
        m = s.get("metrics", {})
        noise = s.get("noise", {})
        lines.append(
            f"| {name} | {s['frames']} | {s['support_found']} | {len(s['empty_frames'])} | "
            f"{_fmt(s['instances_per_frame'], digits=2)} | {_fmt(s.get('on_support_share'))} | "
            f"{_fmt(s['stable_fraction'])} | "
            f"{_fmt(s['resting_fraction'])} | {_fmt(noise.get('held_fraction'))} | "
            f"{_fmt(s['time_s_median'], digits=2)} | "
            f"{_fmt(s['segmentation_s_median'])} | {_fmt(m.get('overlap_f'))} | {_fmt(m.get('boundary_f'))} | "
            f"{_fmt(m.get('f_at_75'))} | {_fmt(m.get('instances_per_object'), digits=2)} | "
            f"{_fmt(m.get('background_fp_fraction'))} |"
        )
    for name, s in summary["sets"].items():
        lines += ["", f"## {name}", ""]
        if s["failed_frames"]:
            lines += [f"- failed: `{frame}`: {error}" for frame, error in s["failed_frames"].items()]
        if s["empty_frames"]:
            lines += [f"- no instance in `{frame}`: {reason}" for frame, reason in s["empty_frames"].items()]
        if "metrics_on_depth" in s:
            m = s["metrics_on_depth"]
            lines.append(
                "- the labels cover only pixels with depth; scored on those pixels: overlap F "
                f"{_fmt(m['overlap_f'])}, boundary F {_fmt(m['boundary_f'])}, F@75 {_fmt(m['f_at_75'])}, "
                f"background FP {_fmt(m['background_fp_fraction'])}"
            )
        if "noise" in s:
            n = s["noise"]
            lines.append(
                f"- under noise: support moved at most {_fmt(n['max_gravity_change_deg'], digits=2)} deg and "
                f"{_fmt(n['max_height_change_m'], 1000, 1)} mm; instance count at most {n['max_instance_change']} "
                f"off; {n['failed_copies']} copies without a support"
            )
        lines += variant_lines(s.get("camera_variants", {}))
        lines += [
            "",
            "| frame | h (m) | inliers | instances | stable | noise: deg / mm / count | overlap F | sheet |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for r in summary["frames"][name]:
            n = r.get("noise", {})
            noise = (
                f"{_fmt(n.get('max_gravity_change_deg'), digits=2)} / {_fmt(n.get('max_height_change_m'), 1000, 1)} / "
                f"{n.get('max_instance_change', '-')}"
            )
            stable = f"{r['stable']}/{len(r['objects'])}" if "objects" in r else "-"
            sheet = f"[png]({r['sheet']})" if "sheet" in r else r["error"]
            lines.append(
                f"| {r['frame']} | {_fmt(r.get('camera_height_m'))} | {_fmt(r.get('inlier_fraction'), digits=2)} | "
                f"{r['instances']} | {stable} | {noise} | {_fmt(r.get('metrics', {}).get('overlap_f'))} | {sheet} |"
            )
    path.write_text("\n".join(lines) + "\n")


def variant_lines(variants: dict) -> list[str]:
    """The report's table of the camera variants of one set ([] without them)."""
    if not variants:
        return []
    lines = [
        "",
        "As other cameras would give these frames (`arm_benchmarks.real.camera_variants`); held: a support "
        "found and the instance count within one of the frame's own instances still in view:",
        "",
        "| camera | support found | empty with objects in view | held | mean count change | overlap F | F@75 |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, v in variants.items():
        m = v.get("metrics", {})
        lines.append(
            f"| {name} | {v['support_found']}/{v['frames']} | {v['empty_with_objects']} | "
            f"{_fmt(v['held_fraction'], digits=2)} | {_fmt(v['mean_instance_change'], digits=2)} | "
            f"{_fmt(m.get('overlap_f'))} | {_fmt(m.get('f_at_75'))} |"
        )
    return lines


def bench_set(folder: pathlib.Path, processor, args) -> list[dict]:
    out_set = args.out / folder.name
    out_set.mkdir(parents=True, exist_ok=True)
    camera = load_camera(find_intrinsics(folder))
    poses = load_poses(folder / POSES_FILE) if (folder / POSES_FILE).is_file() else {}
    frames = find_frames(folder)[: args.max_frames or None]
    rows = []
    for index, files in enumerate(tqdm(frames, desc=folder.name, unit="frame", file=sys.stderr)):
        cache = out_set / "frames" / files.name / BENCH_FILE
        if cache.is_file() and not args.overwrite:
            rows.append(json.loads(cache.read_text()))
            continue
        rng = np.random.default_rng([args.seed, index])
        row = bench_frame(files, camera, poses.get(files.name), out_set, processor, args, rng)
        cache.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_json(cache, json_safe(row), indent=1)
        rows.append(row)
    return rows


def main(argv=None) -> int:
    args = parse_args(argv)
    settings = replace(OfflineSettings(metres_per_depth_unit=args.depth_scale), overwrite=True)
    processor = FrameReconstructor(settings, Reconstructor(settings.reconstruction))
    start = time.time()
    frames = {folder.name: bench_set(folder, processor, args) for folder in args.folders}
    summary = {
        "command": "bench_real " + " ".join(sys.argv[1:] if argv is None else argv),
        "machine": machine_description(),
        "measured_at": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "physics_s": args.physics_s,
        "noise_copies": args.noise_copies,
        "wall_s": time.time() - start,
        "sets": {name: aggregate(rows) for name, rows in frames.items()},
        "frames": frames,
    }
    atomic_write_json(args.out / "summary.json", json_safe(summary), indent=1)
    write_report(args.out / "report.md", summary)
    for name, s in summary["sets"].items():
        m = s.get("metrics", {})
        print(
            f"{name}: support {s['support_found']}/{s['frames']}, {s['instances']} instances, "
            f"stable {_fmt(s['stable_fraction'])}, overlap F {_fmt(m.get('overlap_f'))}"
        )
    print(f"-> {args.out / 'summary.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
