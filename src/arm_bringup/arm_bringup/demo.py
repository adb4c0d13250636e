"""The main job: bring up sim -> segmentation -> reconstruction -> planner as separate processes over
DDS in a seeded cluttered scene (the nodes on the sim's simulated time), run one manipulation request,
and report what the graph produced.

Writes results/demo/{summary.json, camera_segmentation.png, reconstruction_vs_truth.png,
before_after.png}. Stages that are not built yet are skipped and reported as such.
"""

import argparse
import json
import os
import pathlib
import sys
import time

import numpy as np
import rclpy

from arm_bringup.bringup import Graph, node_available
from arm_bringup.observer import Observer
from arm_bringup.plots import plot_before_after, plot_camera_segmentation, plot_reconstruction_vs_truth
from arm_bringup.scenes import reconstruction_errors
from arm_bringup.task import run_task
from arm_ros.common import use_large_socket_buffers
from arm_ros.conversions.images import K_from_camera_info, image_to_numpy
from arm_ros.conversions.poses import pose_to_matrix

ROOT = pathlib.Path(os.environ.get("ARM_ROOT") or pathlib.Path.cwd())
STAGES = ("segmentation", "reconstruction", "planner")
SIM_TOPICS = (
    "camera/color/image_raw",
    "camera/depth/image_raw",
    "camera/camera_info",
    "camera/pose",
    "sim/ground_truth/objects",
    "sim/ground_truth/labels",
)


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--objects", type=int, default=8)
    parser.add_argument("--out", default=str(ROOT / "results" / "demo"))
    parser.add_argument("--task", choices=["grasp", "push", "rearrange"], default="grasp")
    parser.add_argument("--ground-truth-masks", action="store_true", help="segmentation passes the sim's masks through")
    parser.add_argument("--method", default=None, help="reconstruction method (default: the node's, 'arm')")
    return parser.parse_args(argv)


def start_graph(graph: Graph, args) -> list[str]:
    """Start the sim and every built stage; the stages started."""
    graph.start("sim", "-p", f"seed:={args.seed}", "-p", f"n_objects:={args.objects}")
    stages = [k for k in STAGES if node_available(k)]
    for key in stages:
        extra = []
        if key == "segmentation":
            # sim and segmentation share this machine: reliable delivery, so a loaded CPU does not
            # drop every fragmented depth image (the node still keeps only the latest frame)
            extra = ["-p", "image_reliability:=reliable"]
            if args.ground_truth_masks:
                extra += ["-p", "use_ground_truth_masks:=true"]
        if key == "reconstruction" and args.method:
            extra = ["-p", f"method:={args.method}"]
        graph.start(key, *extra)
    return stages


def first_silent_stage(stages, seg_labels, meshes, task) -> str | None:
    """The first running stage whose output never reached the demo (None when all did)."""
    outputs = {"segmentation": seg_labels, "reconstruction": meshes, "planner": task}
    return next((key for key in stages if outputs[key] is None), None)


def run_graph(graph: Graph, node, observer: Observer, args, out: pathlib.Path, summary: dict) -> bool:
    """Drive the graph through segmentation, reconstruction and the task, filling summary and writing
    the figures; False when the sim published nothing."""
    stages = start_graph(graph, args)
    summary["stages"] = {k: ("running" if k in stages or k == "sim" else "not built") for k in ("sim", *STAGES)}
    print(f"[demo] node graph: {summary['stages']}", flush=True)
    if not observer.wait(SIM_TOPICS, 90.0):
        print(f"[demo] the sim published nothing in time: {observer.counts}", file=sys.stderr)
        return False
    truth = observer.latest["sim/ground_truth/objects"]
    T_world_camera = pose_to_matrix(observer.latest["camera/pose"].pose)
    rgb_before, depth = observer.frame()
    gt_labels = image_to_numpy(observer.latest["sim/ground_truth/labels"])
    summary["objects"] = [{"id": o.id, "visible_fraction": round(o.visible_fraction, 3)} for o in truth.objects]
    summary["camera_K"] = K_from_camera_info(observer.latest["camera/camera_info"]).round(2).tolist()

    segmented = None
    if "segmentation" in stages and observer.wait(["arm/segmented_frame"], 120.0):
        segmented = observer.latest["arm/segmented_frame"]

    meshes = None
    if "reconstruction" in stages and observer.wait(["arm/meshes"], 180.0):
        meshes = observer.latest["arm/meshes"]
        summary["reconstruction"] = reconstruction_errors(meshes, truth)
        plot_reconstruction_vs_truth(out / "reconstruction_vs_truth.png", meshes, truth, T_world_camera)
        # Report the segmentation the meshes were built from (frames differ in their noise).
        segmented = observer.segmented_frame_for(meshes.header) or segmented

    seg_labels = None if segmented is None else image_to_numpy(segmented.labels)
    if seg_labels is not None:
        summary["segmented_instances"] = int(len(np.unique(seg_labels)) - 1)
    plot_camera_segmentation(
        out / "camera_segmentation.png",
        rgb_before,
        depth,
        seg_labels if seg_labels is not None else gt_labels,
        seg_labels is not None,
        f"camera (seed {args.seed}, {len(truth.objects)} objects)",
    )

    if "planner" in stages and meshes is not None and meshes.objects:
        summary["task"] = run_task(node, observer, meshes, truth, args.task)
        if observer.wait(["camera/color/image_raw"], 20.0, observer.counts.get("camera/color/image_raw", 0) + 2):
            rgb_after, _ = observer.frame()
            title = f"after {args.task}: success={summary['task'].get('success_in_sim')}"
            plot_before_after(out / "before_after.png", rgb_before, rgb_after, title)

    rclpy.spin_once(node, timeout_sec=0.5)
    summary["failed_stage"] = first_silent_stage(stages, seg_labels, meshes, summary.get("task"))
    summary["latency"] = observer.diagnostics
    summary["alive_at_end"] = graph.alive()
    return True


def main(argv=None) -> int:
    args = parse_args(argv)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    summary = {"seed": args.seed, "stages": {}}
    t_start = time.monotonic()
    use_large_socket_buffers()  # for this process and the graph's, which inherit its environment
    rclpy.init()
    node = rclpy.create_node("arm_demo")
    observer = Observer(node)
    with Graph(ROOT / "log" / "demo", use_sim_time=True) as graph:
        if not run_graph(graph, node, observer, args, out, summary):
            return 1
    summary["wall_s"] = round(time.monotonic() - t_start, 1)
    node.destroy_node()
    rclpy.try_shutdown()
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(json.dumps(summary, indent=2))
    print(f"[demo] wrote {out}")
    if summary["failed_stage"]:
        print(f"[demo] FAILED: {summary['failed_stage']} produced no output (logs in log/demo)", file=sys.stderr)
        return 1
    return 0 if all(summary["alive_at_end"].values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())
