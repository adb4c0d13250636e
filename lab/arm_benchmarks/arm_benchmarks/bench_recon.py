"""bench_recon: ARM against its baselines on cluttered scenes of unseen objects (paper Figure 4).

Each seeded scene drops 3-20 objects (the procedural held-out categories, or the meshes of
--objects DIR at their own size) onto the table, settles them, and renders one random view
(paper's camera distribution, depth noise on). Every object showing >= --min-visible-pixels pixels
with depth is reconstructed from that view, with the ground-truth instance labels or with the
segmentation core's (--segmentation predicted), by every method side by side: visible-only (the
object's observed voxels F1 meshed by the pipeline, no network), baseline, baseline+ray-carving,
baseline+E, arm-c-s, arm-c and arm (arm_reconstruction.pipeline with the shipped checkpoints).

Per object and method: Chamfer distance and volumetric IoU against the true mesh (metrics.py), and
physical stability: all of the method's objects of the view are built into a MuJoCo scene from
convex parts exactly as the planner's twin builds them (arm_planner.twin.usable_parts, ObjectModel,
PlacedObject, arm_sim.world.build_world; table, no robot), simulated --settle-s seconds under
gravity, and the L2 displacement of each object's centre of mass is measured; it is stable when it
moved less than --stable-threshold-m. The true meshes go through the same path as the reference
(decomposed by the pipeline's decomposer, placed at their centroids). An object a method left empty
counts in its IoU as 0 and as not stable, and is left out of its Chamfer mean (counted as empty).

Per-scene results are cached under OUT/cache/<run key>/ (arm_benchmarks.run_key: settings, checkpoints and
the source of every package a result depends on), so an interrupted run resumes. Writes
OUT/summary.json, OUT/report.md, OUT/chamfer_by_visibility.png, OUT/stability.png and
OUT/qualitative.png.

Modules: arm_benchmarks.recon.{config, scenes, matching, physics, scoring, cache, summary, plots,
report}; this one is the command line and the driver.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import sys
import time

import torch
from tqdm import tqdm

from arm_benchmarks.machine import machine_description
from arm_benchmarks.methods import GROUND_TRUTH
from arm_benchmarks.recon.cache import cached_scene, load_cases
from arm_benchmarks.recon.config import ALL_METHODS, PIPELINE_FIELDS, BenchConfig
from arm_benchmarks.recon.plots import plot_by_visibility, plot_qualitative, plot_stability
from arm_benchmarks.recon.report import write_report
from arm_benchmarks.recon.scoring import load_reconstructors
from arm_benchmarks.recon.summary import summarise
from arm_core.settings import add_arguments, from_arguments
from arm_reconstruction.pipeline import ReconstructionSettings
from arm_sim.appearance import DEFAULT_DOMAIN, DOMAINS
from arm_sim.objects import object_pool


def run(config: BenchConfig, progress: bool = True) -> dict:
    """Run (or resume) the benchmark and write its outputs; returns the summary."""
    started, started_cpu = time.perf_counter(), time.process_time()
    torch.set_num_threads(max(1, config.threads))
    reconstructors, skipped, checkpoints = load_reconstructors(config.methods, config.checkpoint_dir, config.pipeline())
    out = pathlib.Path(config.out)
    cache_dir = out / "cache" / config.result_key({c["path"] for c in checkpoints.values()})
    pool = []

    def pool_factory():
        if not pool:
            pool.append(object_pool(config.objects or None, split="heldout", seed=config.seed))
        return pool[0]

    results, computed = [], 0
    for index in tqdm(range(config.scenes), desc="bench_recon scenes", disable=not progress):
        cached = (cache_dir / f"scene_{index:05d}.json").is_file()
        results.append(cached_scene(index, cache_dir, config, pool_factory, reconstructors))
        computed += not cached
    summary = summarise(results, config, skipped, checkpoints)
    figures = ["chamfer_by_visibility.png", "stability.png"]
    plot_by_visibility(summary, out / figures[0])
    plot_stability(summary, out / figures[1])
    cases = load_cases(cache_dir, results, config.qualitative) if config.qualitative else []
    if cases:
        plot_qualitative(cases, out / "qualitative.png")
        figures.append("qualitative.png")
    summary["run"] = {
        "wall_s": time.perf_counter() - started,
        "cpu_s": time.process_time() - started_cpu,
        "scenes_computed": computed,
        "cache": str(cache_dir),
        "machine": machine_description(),
        "cpu_count": os.cpu_count(),
        "load_average": os.getloadavg()[0],
        "command": "bench_recon " + " ".join(sys.argv[1:]),
    }
    write_report(summary, out / "report.md", figures)
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=float))
    return summary


def parse_args(argv=None) -> BenchConfig:
    defaults = BenchConfig()
    parser = argparse.ArgumentParser(
        prog="bench_recon", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--scenes", type=int, default=defaults.scenes, help="number of scenes (one view each)")
    parser.add_argument("--seed", type=int, default=defaults.seed, help="base seed of the scenes")
    parser.add_argument(
        "--objects",
        default="",
        help="folder of .obj/.stl/.ply meshes in metres (default: the procedural held-out categories)",
    )
    parser.add_argument("--segmentation", choices=(GROUND_TRUTH, "predicted"), default=defaults.segmentation)
    parser.add_argument("--out", default=defaults.out, help="output folder")
    parser.add_argument(
        "--methods", default=",".join(ALL_METHODS), help="comma-separated subset of " + ", ".join(ALL_METHODS)
    )
    parser.add_argument("--checkpoint-dir", default="", help="folder with <variant>.pt (default: the shipped ones)")
    parser.add_argument("--min-objects", type=int, default=defaults.min_objects)
    parser.add_argument("--max-objects", type=int, default=defaults.max_objects)
    parser.add_argument(
        "--min-visible-pixels",
        type=int,
        default=defaults.min_visible_pixels,
        help="objects with fewer pixels carrying depth are not evaluated",
    )
    parser.add_argument("--chamfer-samples", type=int, default=defaults.chamfer_samples, help="points per surface")
    parser.add_argument("--iou-resolution", type=int, default=defaults.iou_resolution, help="voxels per side")
    parser.add_argument("--settle-s", type=float, default=defaults.settle_s, help="simulated seconds of gravity")
    parser.add_argument("--physics-timestep-s", type=float, default=defaults.physics_timestep_s)
    parser.add_argument("--stable-threshold-m", type=float, default=defaults.stable_threshold_m)
    parser.add_argument("--no-noise", action="store_true", help="render perfect depth")
    parser.add_argument("--domain", choices=DOMAINS, default=DEFAULT_DOMAIN, help="visual domain of the scenes")
    pipeline_flags = add_arguments(parser, ReconstructionSettings(), PIPELINE_FIELDS)
    parser.add_argument(
        "--view",
        choices=("occluded", "random"),
        default=defaults.view,
        help="occluded: of --view-candidates random views keep the one with the most partly occluded objects",
    )
    parser.add_argument("--view-candidates", type=int, default=defaults.view_candidates)
    parser.add_argument("--qualitative", type=int, default=defaults.qualitative, help="rows of qualitative.png")
    parser.add_argument("--threads", type=int, default=defaults.threads, help="torch CPU threads")
    args = parser.parse_args(argv)
    methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    unknown = [m for m in methods if m not in ALL_METHODS]
    if unknown or not methods:
        parser.error(f"unknown methods {unknown}; choose from {', '.join(ALL_METHODS)}")
    if args.scenes < 1 or not 1 <= args.min_objects <= args.max_objects or args.min_visible_pixels < 10:
        parser.error("need --scenes >= 1, 1 <= --min-objects <= --max-objects, --min-visible-pixels >= 10")
    if args.chamfer_samples < 1 or args.iou_resolution < 8 or args.settle_s <= 0 or args.stable_threshold_m <= 0:
        parser.error("need --chamfer-samples >= 1, --iou-resolution >= 8, positive --settle-s and threshold")
    try:
        pipeline = from_arguments(ReconstructionSettings(), args, pipeline_flags)
    except ValueError as error:
        parser.error(str(error))
    if not 0 < args.physics_timestep_s <= 0.02 or min(args.threads, args.view_candidates) < 1 or args.qualitative < 0:
        parser.error("need 0 < --physics-timestep-s <= 0.02, --threads and --view-candidates >= 1, --qualitative >= 0")
    return BenchConfig(
        scenes=args.scenes,
        seed=args.seed,
        objects=args.objects,
        segmentation=args.segmentation,
        out=args.out,
        methods=tuple(m for m in ALL_METHODS if m in methods),
        checkpoint_dir=args.checkpoint_dir,
        min_objects=args.min_objects,
        max_objects=args.max_objects,
        min_visible_pixels=args.min_visible_pixels,
        chamfer_samples=args.chamfer_samples,
        iou_resolution=args.iou_resolution,
        settle_s=args.settle_s,
        physics_timestep_s=args.physics_timestep_s,
        stable_threshold_m=args.stable_threshold_m,
        depth_noise=not args.no_noise,
        domain=args.domain,
        **{name: getattr(pipeline, name) for name in PIPELINE_FIELDS},
        view=args.view,
        view_candidates=args.view_candidates,
        qualitative=args.qualitative,
        threads=args.threads,
    )


def main(argv=None) -> int:
    config = parse_args(argv)
    try:
        summary = run(config)
    except KeyboardInterrupt:
        print("bench_recon: interrupted; finished scenes are cached and the next run resumes", file=sys.stderr)
        return 130
    print(f"bench_recon: {summary['objects']} objects in {summary['scenes']} scenes -> {config.out}/report.md")
    for name, m in summary["methods"].items():
        if m["status"] != "ok":
            print(f"  {name:22s} skipped: {m['reason']}")
            continue
        chamfer = "-" if m["chamfer_m"] is None else f"{m['chamfer_m'] * 1000:.2f} mm"
        iou = "-" if m["iou"] is None else f"{m['iou']:.3f}"
        normals = "-" if m.get("normal_consistency") is None else f"{m['normal_consistency']:.3f}"
        stable = "-" if m["stable_fraction"] is None else f"{m['stable_fraction']:.3f}"
        print(f"  {name:22s} Chamfer {chamfer:>9s}  normals {normals:>5s}  IoU {iou:>5s}  stable {stable}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
