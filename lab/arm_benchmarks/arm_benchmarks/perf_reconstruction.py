"""Inference-path performance: one simulated 10-object RGB-D frame -> meshes ready to publish.

measure() times every stage (message decoding, grids, network, post-processing, marching cubes,
intersection removal, convex decomposition, visibility, message encoding) over several repeats and
reports medians, plus a resolution study (32 vs 64) and the convex decomposition's faithfulness
(volume IoU of the union of parts vs the mesh) against tuned CoACD. When no trained checkpoint
exists, the network is timed with untrained weights and the stages after it run on ground-truth
occupancy; the summary says which (weights field).
"""

import argparse
import json
import os
import pathlib
import platform
import time

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
import torch
from std_msgs.msg import Header
from tqdm import tqdm

from arm_benchmarks.stats import median
from arm_core.camera import look_at
from arm_core.heap import freeze_startup_objects
from arm_reconstruction.checkpoint import default_checkpoint_path
from arm_reconstruction.convex_parts import ConvexDecomposer, DecompositionSettings, decomposition_iou
from arm_reconstruction.grid import frame_grids, voxelize_mesh
from arm_reconstruction.messages import main_table_height, markers_msg, objects_to_msg
from arm_reconstruction.network import METHODS, build_model, predict_occupancy, prepare_for_inference
from arm_reconstruction.pipeline import STAGES, ReconstructionSettings, Reconstructor
from arm_ros.conversions.frames import frame_from_msg, segmented_frame_msg
from arm_sim.objects import object_pool
from arm_sim.views import BenchmarkScene

matplotlib.use("Agg")

MIN_VISIBLE_PIXELS = 150


def simulated_frame(n_objects: int = 10, seed: int = 0, width: int = 640, height: int = 480, max_tries: int = 40):
    """A settled cluttered scene and a noisy RGB-D frame in which all n_objects are visible."""
    rng = np.random.default_rng(seed)
    pool = object_pool(split="heldout", seed=seed)
    best = None
    for _ in range(max_tries):
        with BenchmarkScene(pool, rng, n_objects, width=width, height=height) as views:
            scene = views.scene
            if len(scene.objects) < n_objects:
                continue
            centre = np.mean([o.T_world_object[:3, 3] for o in scene.objects], axis=0)
            for _ in range(4):
                azimuth = rng.uniform(0, 2 * np.pi)
                eye = centre + np.array([0.55 * np.cos(azimuth), 0.55 * np.sin(azimuth), rng.uniform(0.45, 0.7)])
                frame = views.render(look_at(eye, centre))
                counts = np.bincount(frame.labels.ravel(), minlength=n_objects + 1)[1 : n_objects + 1]
                visible = int(np.sum(counts >= MIN_VISIBLE_PIXELS))
                if best is None or visible > best[0]:
                    best = (visible, scene, frame)
                if visible == n_objects:
                    return scene, frame
    if best is None:
        raise RuntimeError("could not build a scene")
    return best[1], best[2]


def _median_ms(samples: list[float]) -> float:
    return median(samples) * 1000.0


def _time_network(variant: str, resolution: int, grids: np.ndarray, repeats: int) -> float:
    model = prepare_for_inference(build_model(variant, resolution))
    predict_occupancy(model, grids[:2])
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        predict_occupancy(model, grids)
        times.append(time.perf_counter() - start)
    return _median_ms(times) / len(grids)


def resolution_study(frame, resolutions=(32, 64), repeats: int = 2) -> dict:
    """Grid and network cost per object at each resolution (untrained weights: timing only)."""
    study = {}
    for d in resolutions:
        times, grids = [], None
        for _ in range(repeats + 1):
            start = time.perf_counter()
            grids = frame_grids(frame.depth_m, frame.K, frame.T_world_camera, frame.labels, resolution=d)
            times.append(time.perf_counter() - start)
        n = len(grids.object_ids)
        study[str(d)] = {
            "grid_ms_per_object": _median_ms(times[1:]) / n,
            "network_ms_per_object": _time_network("arm", d, grids.grids, repeats),
            "objects": n,
        }
    return study


def decomposition_study(meshes, include_coacd: bool = True) -> dict:
    """Time, parts and IoU(union of parts, mesh) per decomposition method on the frame's meshes."""
    methods = ["planes"] + (["coacd"] if include_coacd else [])
    study = {}
    for method in methods:
        decomposer = ConvexDecomposer(DecompositionSettings(method=method))
        times, ious, parts = [], [], []
        for mesh in meshes:
            start = time.perf_counter()
            result = decomposer(mesh)
            times.append(time.perf_counter() - start)
            ious.append(decomposition_iou(mesh, result))
            parts.append(result)
        study[method] = {
            "ms_per_object": float(np.mean(times) * 1000.0),
            "iou_min": float(np.min(ious)),
            "iou_mean": float(np.mean(ious)),
            "parts_mean": float(np.mean([len(p) for p in parts])),
            "parts_max": int(max(len(p) for p in parts)),
            "vertices_per_part_max": int(max((len(q.vertices) for p in parts for q in p), default=0)),
            "objects": len(meshes),
        }
    return study


def measure(
    checkpoint_path: str = "",
    method: str = "arm",
    n_objects: int = 10,
    repeats: int = 3,
    seed: int = 0,
    threads: int = 2,
    include_coacd: bool = True,
    resolutions=(32, 64),
) -> dict:
    """Per-stage latency of one frame -> meshes on this machine; see the module docstring."""
    torch.set_num_threads(threads)
    scene, frame = simulated_frame(n_objects, seed)
    variant = METHODS[method][0]
    path = pathlib.Path(checkpoint_path) if checkpoint_path else default_checkpoint_path(variant)
    trained = path.is_file()
    settings = ReconstructionSettings(method=method, checkpoint_path=str(path) if trained else "")
    reconstructor = Reconstructor(settings, model=None if trained else build_model(variant, 32))
    message = segmented_frame_msg(frame, Header())
    freeze_startup_objects()  # as every node does once it is built (arm_ros.common.run_node)

    stage_samples = {stage: [] for stage in ("decode", *STAGES, "encode", "markers", "total")}
    cpu_samples = []
    stage_cpu_samples = {stage: [] for stage in STAGES}
    objects = []
    for repeat in tqdm(range(repeats + 1), desc="perf frames", leave=False):
        reconstructor.decomposer.clear_cache()
        cpu_start = time.process_time()
        start = time.perf_counter()
        data = frame_from_msg(message)
        decoded = time.perf_counter()
        reconstructor.timer.reset()
        grids = reconstructor.grids(data.depth_m, data.K, data.T_world_camera, data.labels)
        probabilities = reconstructor.predict(grids)
        if not trained:  # untrained weights: the later stages run on ground-truth occupancy
            pairs = zip(grids.object_ids, grids.frames, strict=True)
            probabilities = np.stack([voxelize_mesh(scene.objects[i - 1].world_mesh(), f) for i, f in pairs]).astype(
                np.float32
            )
        oracle_s = time.perf_counter()
        objects = reconstructor.build_objects(
            grids, probabilities, data.depth_m, data.labels, data.K, data.T_world_camera
        )
        built = time.perf_counter()
        objects_to_msg(objects, message.header, main_table_height(objects))
        end = time.perf_counter()  # the node publishes /arm/meshes here, then builds the RViz markers
        markers_msg(objects, message.header)
        markers_end = time.perf_counter()
        cpu_s = time.process_time() - cpu_start
        if repeat == 0:
            continue  # warm-up
        stage_samples["decode"].append(decoded - start)
        for stage in STAGES:
            stage_samples[stage].append(reconstructor.last_timings_s[stage])
            stage_cpu_samples[stage].append(reconstructor.last_cpu_s[stage])
        stage_samples["encode"].append(end - built)
        stage_samples["markers"].append(markers_end - end)
        before_oracle = sum(reconstructor.last_timings_s[s] for s in ("grid", "network", "postprocess"))
        stage_samples["total"].append((decoded - start) + before_oracle + (built - oracle_s) + (end - built))
        cpu_samples.append(cpu_s)

    stages_ms = {stage: _median_ms(samples) for stage, samples in stage_samples.items()}
    n = len(grids.object_ids)
    meshes = [o.mesh for o in objects if o.ok]
    result = {
        "process": {
            "cpu_count": os.cpu_count(),
            "torch_threads": torch.get_num_threads(),
            "load_average_1m_at_end": float(os.getloadavg()[0]),
            "processor": platform.processor() or platform.machine(),
            "cuda": torch.cuda.is_available(),
        },
        "scene": {
            "objects_in_scene": len(scene.objects),
            "objects_reconstructed": n,
            "image": list(frame.depth_m.shape),
        },
        "method": method,
        "resolution": reconstructor.resolution,
        "weights": f"checkpoint {path}"
        if trained
        else "untrained (network timing only; later stages on ground-truth occupancy)",
        "repeats": repeats,
        "grid_ms_per_object": stages_ms["grid"] / n,
        "network_ms_per_object": stages_ms["network"] / n,
        "decomposition_ms_per_object": stages_ms["decomposition"] / max(len(meshes), 1),
        "frame_to_meshes_s": stages_ms["total"] / 1000.0,
        "frame_process_cpu_s": median(cpu_samples),
        "stages_ms": stages_ms,
        "stages_process_cpu_ms": {stage: _median_ms(samples) for stage, samples in stage_cpu_samples.items()},
        "objects_ok": len(meshes),
        "resolution_study": resolution_study(frame, resolutions),
        "decomposition_study": decomposition_study(meshes, include_coacd),
    }
    return result


def write_report(result: dict, out_dir="results/perf") -> None:
    """Merge the figures into out_dir/summary.json and write reconstruction.md and reconstruction_stages.png."""
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summary_path = out / "summary.json"
    summary = json.loads(summary_path.read_text()) if summary_path.is_file() else {}
    for key in ("grid_ms_per_object", "network_ms_per_object", "decomposition_ms_per_object", "frame_to_meshes_s"):
        summary[key] = round(result[key], 4)
    summary["reconstruction"] = result
    summary_path.write_text(json.dumps(summary, indent=2))

    stages = {k: v for k, v in result["stages_ms"].items() if k not in ("total", "markers")}
    figure, (left, right) = plt.subplots(1, 2, figsize=(11, 4))
    left.barh(list(stages), list(stages.values()), color="tab:blue")
    left.set_xlabel("ms per frame")
    left.set_title(f"{result['scene']['objects_reconstructed']} objects: {result['frame_to_meshes_s']:.2f} s total")
    left.invert_yaxis()
    study = result["resolution_study"]
    labels = list(study)
    x = np.arange(len(labels))
    right.bar(x - 0.2, [study[d]["grid_ms_per_object"] for d in labels], 0.4, label="grid")
    right.bar(x + 0.2, [study[d]["network_ms_per_object"] for d in labels], 0.4, label="network")
    right.set_xticks(x, [f"d = {d}" for d in labels])
    right.set_ylabel("ms per object")
    right.set_yscale("log")
    right.legend()
    right.set_title("resolution")
    figure.tight_layout()
    figure.savefig(out / "reconstruction_stages.png", dpi=120)
    plt.close(figure)

    m = result["process"]
    height, width = result["scene"]["image"]
    lines = [
        "# Reconstruction inference performance",
        "",
        f"{m['cpu_count']} CPU cores, {m['torch_threads']} torch threads, 1-min load average at the end "
        f"{m['load_average_1m_at_end']:.1f}; method `{result['method']}`, d = {result['resolution']}, "
        f"{result['scene']['objects_reconstructed']} objects, {width}x{height} frame, "
        f"median of {result['repeats']} repeats. Weights: {result['weights']}. Process CPU time per frame "
        f"(all threads): {result['frame_process_cpu_s']:.2f} s; wall-clock figures grow with the machine's load.",
        "",
        "| figure | value | target |",
        "|---|---|---|",
        f"| grid_ms_per_object | {result['grid_ms_per_object']:.1f} | <= 20 |",
        f"| network_ms_per_object | {result['network_ms_per_object']:.1f} | <= 50 |",
        f"| decomposition_ms_per_object | {result['decomposition_ms_per_object']:.1f} | |",
        f"| frame_to_meshes_s (to /arm/meshes; RViz markers after) | {result['frame_to_meshes_s']:.3f} | <= 1.0 |",
        "",
        "| stage | wall ms per frame | process CPU ms (all threads) |",
        "|---|---|---|",
        *[
            f"| {k} | {v:.1f} | {result['stages_process_cpu_ms'].get(k, float('nan')):.1f} |"
            for k, v in result["stages_ms"].items()
        ],
        "",
        "| resolution | grid ms/object | network ms/object |",
        "|---|---|---|",
        *[f"| {d} | {v['grid_ms_per_object']:.1f} | {v['network_ms_per_object']:.1f} |" for d, v in study.items()],
        "",
        "| decomposition | ms/object | IoU min | IoU mean | parts mean | max vertices/part |",
        "|---|---|---|---|---|---|",
        *[
            f"| {k} | {v['ms_per_object']:.1f} | {v['iou_min']:.3f} | {v['iou_mean']:.3f} | {v['parts_mean']:.1f} "
            f"| {v['vertices_per_part_max']} |"
            for k, v in result["decomposition_study"].items()
        ],
        "",
        "![stages](reconstruction_stages.png)",
    ]
    (out / "reconstruction.md").write_text("\n".join(lines) + "\n")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="Time the reconstruction inference path on a 10-object frame")
    parser.add_argument("--checkpoint", default="", help="checkpoint (default: the shipped one of --method)")
    parser.add_argument("--method", default="arm", choices=sorted(METHODS))
    parser.add_argument("--objects", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--no-coacd", action="store_true", help="skip the CoACD comparison")
    parser.add_argument("--out", default="results/perf")
    args = parser.parse_args(argv)
    result = measure(
        args.checkpoint, args.method, args.objects, args.repeats, args.seed, args.threads, not args.no_coacd
    )
    write_report(result, args.out)
    keys = ("grid_ms_per_object", "network_ms_per_object", "decomposition_ms_per_object", "frame_to_meshes_s")
    print(json.dumps({k: round(result[k], 4) for k in keys}, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
