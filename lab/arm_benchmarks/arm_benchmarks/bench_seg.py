"""bench_seg: unseen-object instance segmentation quality and latency on simulated cluttered scenes.

N seeded scenes (3-20 held-out objects each, settled by physics, camera pose sampled as in the
paper's benchmark, depth noise on) are rendered at 640x480 and segmented by the default method
(geometry, colour and the learned merge classifier), by it with the hand-made colour and
smooth-surface merging instead of the classifier, without the learned outline pass, and by the classic
baseline (RANSAC plane + DBSCAN). All are scored with the
UOIS metrics (overlap and boundary P/R/F, F@75%) on all scenes and on the dense subset (>= 12
objects), and timed per frame.

Rendered frames and per-scene scores are kept under OUT/cache/, so an interrupted run resumes where
it stopped. Frames are keyed by the run key of the settings and the simulator's source, scores by the
run key of the settings, the boundary network's and merge classifier's weights and the source of the simulator, the
segmentation and this package, so changed code or weights render and score anew (arm_benchmarks.run_key).
Writes OUT/summary.json, OUT/report.md, OUT/examples.png and OUT/metrics.png.
"""

import argparse
import functools
import json
import os
import pathlib
import time

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
from tqdm import tqdm

from arm_benchmarks.machine import machine_description
from arm_benchmarks.run_key import run_key
from arm_benchmarks.stats import mean, median, percentile
from arm_core.atomic_io import atomic_write
from arm_segmentation.baseline import segment_baseline
from arm_segmentation.boundary_net import DEFAULT_CHECKPOINT
from arm_segmentation.merge_model import DEFAULT_CHECKPOINT as MERGE_CHECKPOINT
from arm_segmentation.merge_model import MergeParams
from arm_segmentation.metrics import segmentation_metrics
from arm_segmentation.outline_model import DEFAULT_CHECKPOINT as OUTLINE_CHECKPOINT
from arm_segmentation.outline_model import OutlineParams
from arm_segmentation.segmentation import SegmentationParams, segment
from arm_segmentation.visualization import colourise
from arm_sim.appearance import DEFAULT_DOMAIN, DOMAINS
from arm_sim.objects import object_pool
from arm_sim.views import render_benchmark_view

matplotlib.use("Agg")

COLOUR_MERGE = SegmentationParams(merge=MergeParams(enabled=False))
NO_OUTLINE_PASS = SegmentationParams(outline=OutlineParams(enabled=False))
METHODS = {
    "arm_default": segment,
    "arm_colour_merge": functools.partial(segment, params=COLOUR_MERGE),
    "arm_colour_outline": functools.partial(segment, params=NO_OUTLINE_PASS),
    "baseline_ransac_dbscan": segment_baseline,
}
METRIC_KEYS = (
    "overlap_precision",
    "overlap_recall",
    "overlap_f",
    "boundary_precision",
    "boundary_recall",
    "boundary_f",
    "f_at_75",
    "instances_per_object",
    "background_fp_fraction",
)


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", type=int, default=20, help="number of simulated scenes")
    parser.add_argument("--seed", type=int, default=0, help="base seed of the scenes")
    parser.add_argument(
        "--objects",
        default=None,
        help="folder of .obj/.stl/.ply meshes used as the object pool (default: the procedural held-out categories)",
    )
    parser.add_argument("--out", default="results/seg", help="output folder")
    parser.add_argument("--min-objects", type=int, default=3)
    parser.add_argument("--max-objects", type=int, default=20)
    parser.add_argument(
        "--dense", type=int, default=12, help="scenes with at least this many objects form the dense subset"
    )
    parser.add_argument("--no-noise", action="store_true", help="render perfect depth")
    parser.add_argument(
        "--domain", choices=DOMAINS, default=DEFAULT_DOMAIN, help="visual domain of the rendered scenes"
    )
    parser.add_argument("--examples", type=int, default=4, help="example frames in examples.png")
    args = parser.parse_args(argv)
    if args.scenes < 1 or not 1 <= args.min_objects <= args.max_objects:
        parser.error("need --scenes >= 1 and 1 <= --min-objects <= --max-objects")
    return args


FRAME_PACKAGES = ("arm_core", "arm_sim")
SCORE_PACKAGES = (*FRAME_PACKAGES, "arm_segmentation", "arm_benchmarks")


def frame_settings(args) -> dict:
    objects = str(pathlib.Path(args.objects).resolve()) if args.objects else "heldout"
    return {
        "seed": args.seed,
        "objects": objects,
        "min_objects": args.min_objects,
        "max_objects": args.max_objects,
        "depth_noise": not args.no_noise,
        "domain": args.domain,
    }


def frames_key(args) -> str:
    """Run key of the rendered frames: settings and the simulator's source."""
    return run_key(frame_settings(args), packages=FRAME_PACKAGES)


def scores_key(args) -> str:
    """Run key of the per-scene scores: settings, the simulator's, the segmentation's and this package's source."""
    checkpoints = [DEFAULT_CHECKPOINT, MERGE_CHECKPOINT, OUTLINE_CHECKPOINT]
    return run_key(frame_settings(args), checkpoints=checkpoints, packages=SCORE_PACKAGES)


def render_scene(index: int, args, pool):
    """Build, settle and render scene `index` (deterministic in seed and index)."""
    rng = np.random.default_rng([args.seed, index])
    scene, frame = render_benchmark_view(
        pool,
        rng,
        (args.min_objects, args.max_objects),
        depth_noise=not args.no_noise,
        with_visibility=False,
        domain=args.domain,
    )
    return {
        "rgb": frame.rgb,
        "depth": frame.depth_m,
        "labels": frame.labels,
        "K": frame.K,
        "T": frame.T_world_camera,
        "n_objects": len(scene.objects),
    }


def load_or_render(index: int, args, pool_factory, frames_dir: pathlib.Path):
    path = frames_dir / f"{index:04d}.npz"
    if path.exists():
        with np.load(path) as data:
            return {k: data[k] for k in data.files}
    frame = render_scene(index, args, pool_factory())
    atomic_write(path, lambda tmp: np.savez_compressed(tmp, **frame))
    return frame


def score_scene(frame) -> dict:
    gt = frame["labels"]
    result = {"n_objects": int(frame["n_objects"]), "n_visible": int(np.count_nonzero(np.unique(gt)))}
    for name, method in METHODS.items():
        start, start_cpu = time.perf_counter(), time.process_time()
        labels = method(frame["rgb"], frame["depth"], frame["K"], frame["T"])
        latency_ms = 1e3 * (time.perf_counter() - start)
        cpu_ms = 1e3 * (time.process_time() - start_cpu)
        metrics = segmentation_metrics(labels, gt)
        result[name] = {
            **{k: float(metrics[k]) for k in METRIC_KEYS},
            "n_pred": metrics["n_pred"],
            "latency_ms": latency_ms,
            "cpu_ms": cpu_ms,
        }
    return result


def aggregate(rows: list[dict]) -> dict:
    if not rows:
        return {}
    out = {}
    for name in METHODS:
        out[name] = {k: mean([r[name][k] for r in rows if np.isfinite(r[name][k])]) for k in METRIC_KEYS}
        latencies = [r[name]["latency_ms"] for r in rows]
        out[name]["latency_ms_median"] = median(latencies)
        out[name]["latency_ms_p90"] = percentile(latencies, 90)
        out[name]["cpu_ms_median"] = median([r[name].get("cpu_ms", np.nan) for r in rows])
    return out


def write_examples(path: pathlib.Path, frames: list, titles: list[str]) -> None:
    columns = ["RGB", "ground truth", "arm_default", "arm_colour_merge", "baseline_ransac_dbscan"]
    fig, axes = plt.subplots(len(frames), len(columns), figsize=(4 * len(columns), 3.1 * len(frames)), squeeze=False)
    for row, (frame, title) in enumerate(zip(frames, titles, strict=True)):
        images = [frame["rgb"], colourise(frame["labels"])]
        images += [colourise(METHODS[m](frame["rgb"], frame["depth"], frame["K"], frame["T"])) for m in columns[2:]]
        for col, image in enumerate(images):
            ax = axes[row, col]
            ax.imshow(image)
            ax.set_xticks([])
            ax.set_yticks([])
            if row == 0:
                ax.set_title(columns[col])
        axes[row, 0].set_ylabel(title)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def write_metric_plot(path: pathlib.Path, subsets: dict) -> None:
    keys = ("overlap_f", "boundary_f", "f_at_75")
    fig, axes = plt.subplots(1, len(subsets), figsize=(6 * len(subsets), 4), squeeze=False)
    for ax, (subset, stats) in zip(axes[0], subsets.items(), strict=True):
        x = np.arange(len(keys))
        for i, name in enumerate(METHODS):
            if name in stats:
                ax.bar(x + 0.38 * i, [stats[name][k] for k in keys], 0.38, label=name)
        ax.set_xticks(x + 0.19, keys)
        ax.set_ylim(0, 1)
        ax.set_title(f"{subset} ({stats.get('scenes', 0)} scenes)")
        ax.legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def write_report(path: pathlib.Path, summary: dict, args) -> None:
    lines = ["# Unseen-object instance segmentation benchmark", ""]
    lines.append(
        f"{summary['scenes']} simulated cluttered scenes ({args.min_objects}-{args.max_objects} objects, "
        f"pool: {summary['object_pool']}, {args.domain} visual domain, seed {args.seed}, depth noise "
        f"{'off' if args.no_noise else 'on'}), 640x480 frames. Metrics as in the UOIS papers "
        "(Hungarian matching on overlap F; boundary tolerance ceil(0.003 x diagonal) px), averaged "
        "over frames. Latency: wall time per frame on this machine "
        f"({summary['machine']}, {summary['cpu_count']} CPUs, load average {summary['load_average']:.1f} "
        "while measured: the wall time includes waiting for a core); CPU: process CPU time per frame."
    )
    lines.append("")
    for subset, stats in summary["subsets"].items():
        lines.append(f"## {subset}: {stats.get('scenes', 0)} scenes")
        lines.append("")
        lines.append(
            "| method | overlap P | overlap R | overlap F | boundary P | boundary R | boundary F | F@75% "
            "| instances per object | background FP | latency median ms | p90 ms | CPU median ms |"
        )
        lines.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for name in METHODS:
            if name not in stats:
                continue
            s = stats[name]
            lines.append(
                f"| {name} | {s['overlap_precision']:.3f} | {s['overlap_recall']:.3f} | "
                f"{s['overlap_f']:.3f} | {s['boundary_precision']:.3f} | {s['boundary_recall']:.3f} | "
                f"{s['boundary_f']:.3f} | {s['f_at_75']:.3f} | {s['instances_per_object']:.2f} | "
                f"{s['background_fp_fraction']:.3f} | {s['latency_ms_median']:.0f} | "
                f"{s['latency_ms_p90']:.0f} | {s['cpu_ms_median']:.0f} |"
            )
        lines.append("")
    gain = summary.get("dense_overlap_f_gain_over_baseline")
    if gain is not None:
        lines.append(f"Dense subset: the default method's overlap F is {gain:+.3f} relative to the baseline.")
        lines.append("")
    lines.append("![examples](examples.png)")
    lines.append("")
    lines.append("![metrics](metrics.png)")
    path.write_text("\n".join(lines) + "\n")


def main(argv=None) -> int:
    args = parse_args(argv)
    import torch

    torch.set_num_threads(1)  # as segmentation_node runs the outline network; idle threads would bill CPU to the rest
    out = pathlib.Path(args.out)
    frames_dir = out / "cache" / frames_key(args)
    frames_dir.mkdir(parents=True, exist_ok=True)
    scores_path = frames_dir / f"scores_{scores_key(args)}.jsonl"
    done = {}
    if scores_path.exists():
        for line in scores_path.read_text().splitlines():
            if line.strip():
                row = json.loads(line)
                done[row["index"]] = row
    pool_cache = {}

    def pool_factory():
        if "pool" not in pool_cache:
            pool_cache["pool"] = object_pool(args.objects, split="heldout", seed=args.seed)
        return pool_cache["pool"]

    rows = []
    with scores_path.open("a") as scores:
        for index in tqdm(range(args.scenes), desc="bench_seg", unit="scene"):
            if index in done:
                rows.append(done[index])
                continue
            frame = load_or_render(index, args, pool_factory, frames_dir)
            row = {"index": index, **score_scene(frame)}
            scores.write(json.dumps(row) + "\n")
            scores.flush()
            rows.append(row)

    dense = [r for r in rows if r["n_objects"] >= args.dense]
    subsets = {
        "all": {"scenes": len(rows), **aggregate(rows)},
        f"dense (>= {args.dense} objects)": {"scenes": len(dense), **aggregate(dense)},
    }
    summary = {
        "scenes": len(rows),
        "dense_scenes": len(dense),
        "methods": {name: {**subsets["all"][name], "dense": aggregate(dense).get(name, {})} for name in METHODS},
        "subsets": subsets,
        "object_pool": args.objects or "procedural held-out categories",
        "seed": args.seed,
        "depth_noise": not args.no_noise,
        "domain": args.domain,
        "machine": machine_description(),
        "cpu_count": os.cpu_count(),
        "load_average": os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan"),
        "measured_at": time.strftime("%Y-%m-%dT%H:%M:%S"),
    }
    if dense:
        summary["dense_overlap_f_gain_over_baseline"] = (
            summary["methods"]["arm_default"]["dense"]["overlap_f"]
            - summary["methods"]["baseline_ransac_dbscan"]["dense"]["overlap_f"]
        )
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    examples = sorted(rows, key=lambda r: r["n_objects"])
    picks = [
        examples[int(round(q * (len(examples) - 1)))]["index"]
        for q in np.linspace(0, 1, min(args.examples, len(examples)))
    ]
    picks = list(dict.fromkeys(picks))
    frames = [load_or_render(i, args, pool_factory, frames_dir) for i in picks]
    if frames:  # --examples 0: no examples.png
        write_examples(
            out / "examples.png",
            frames,
            [f"scene {i} ({int(f['n_objects'])} objects)" for i, f in zip(picks, frames, strict=True)],
        )
    write_metric_plot(out / "metrics.png", subsets)
    write_report(out / "report.md", summary, args)
    for subset, stats in subsets.items():
        print(f"[bench_seg] {subset}: {stats['scenes']} scenes")
        for name in METHODS:
            if name in stats:
                s = stats[name]
                print(
                    f"  {name:24s} overlap F {s['overlap_f']:.3f}  boundary F {s['boundary_f']:.3f}  "
                    f"F@75 {s['f_at_75']:.3f}  instances/object {s['instances_per_object']:.2f}  "
                    f"background FP {s['background_fp_fraction']:.3f}  latency {s['latency_ms_median']:.0f} ms"
                )
    print(f"[bench_seg] wrote {out / 'summary.json'}, {out / 'report.md'}, examples.png, metrics.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
