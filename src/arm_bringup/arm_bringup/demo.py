"""The main job: bring up sim -> segmentation -> reconstruction -> planner as separate processes over
DDS in a seeded cluttered scene, run one manipulation request, and report what the graph produced.

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

ROOT = pathlib.Path(os.environ.get("ARM_ROOT") or pathlib.Path.cwd())

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import rclpy  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseArray, PoseStamped  # noqa: E402
from rclpy.action import ActionClient  # noqa: E402
from sensor_msgs.msg import CameraInfo, Image, JointState  # noqa: E402

from arm_bringup.bringup import Graph, node_available  # noqa: E402
from arm_core.camera import look_at  # noqa: E402
from arm_interfaces.action import Manipulate  # noqa: E402
from arm_interfaces.msg import ReconstructedObjectArray, SegmentedFrame  # noqa: E402
from arm_ros.common import latched_qos, sensor_qos  # noqa: E402
from arm_ros.conversions.images import K_from_camera_info, depth_to_metres, image_to_numpy  # noqa: E402
from arm_ros.conversions.meshes import reconstructed_object_from_msg  # noqa: E402
from arm_ros.conversions.poses import pose_to_matrix  # noqa: E402
from arm_sim.objects import ObjectModel  # noqa: E402
from arm_sim.scenes import PlacedObject, Scene  # noqa: E402
from arm_sim.world import ROBOT_BASE_XY, SimWorld  # noqa: E402


class Observer:
    """Collects the latest message of every topic the demo reports on."""

    def __init__(self, node):
        self.node, self.latest, self.counts = node, {}, {}
        self.diagnostics: dict[str, dict] = {}
        qos = sensor_qos("reliable")
        for topic, kind, profile in [
            ("camera/color/image_raw", Image, qos),
            ("camera/depth/image_raw", Image, qos),
            ("camera/camera_info", CameraInfo, qos),
            ("camera/pose", PoseStamped, qos),
            ("sim/ground_truth/labels", Image, qos),
            ("arm/segmented_frame", SegmentedFrame, 2),
            ("arm/meshes", ReconstructedObjectArray, latched_qos()),
            ("sim/ground_truth/objects", ReconstructedObjectArray, latched_qos()),
            ("joint_states", JointState, 10),
            ("sim/ground_truth/poses", PoseArray, 10),
        ]:
            node.create_subscription(kind, topic, lambda m, t=topic: self._store(t, m), profile)
        node.create_subscription(DiagnosticArray, "diagnostics", self._diag, 50)

    def _store(self, topic, msg):
        self.latest[topic] = msg
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def _diag(self, msg):
        for status in msg.status:
            self.diagnostics[status.name] = {kv.key: kv.value for kv in status.values}

    def wait(self, topics, timeout_s: float, min_count: int = 1) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            rclpy.spin_once(self.node, timeout_sec=0.05)
            if all(self.counts.get(t, 0) >= min_count for t in topics):
                return True
        return False

    def frame(self):
        rgb = image_to_numpy(self.latest["camera/color/image_raw"])
        depth = depth_to_metres(self.latest["camera/depth/image_raw"])
        return rgb, depth


def chamfer_m(mesh_a, mesh_b, samples: int = 3000) -> float:
    """Symmetric Chamfer distance: the mean over both directions of the mean nearest-neighbour
    distance between points sampled uniformly on the two surfaces, metres."""
    from scipy.spatial import cKDTree

    a, b = mesh_a.sample(samples), mesh_b.sample(samples)
    return 0.5 * float(cKDTree(b).query(a)[0].mean() + cKDTree(a).query(b)[0].mean())


def objects_to_scene(msg: ReconstructedObjectArray) -> tuple[Scene, list]:
    import trimesh

    objects, meshes = [], []
    for obj in msg.objects:
        T, (v, f), parts = reconstructed_object_from_msg(obj)
        mesh = trimesh.Trimesh(v, f, process=False)
        world = mesh.copy().apply_transform(T)
        hulls = [trimesh.Trimesh(pv, pf, process=False) for pv, pf in parts] or [mesh.convex_hull]
        colour = tuple(np.random.default_rng(obj.id).uniform(0.2, 0.9, 3)) + (1.0,)
        objects.append(PlacedObject(ObjectModel(f"id{obj.id}", "msg", mesh, hulls), 1.0, T, colour))
        meshes.append((obj.id, world))
    return Scene(objects, msg.table_height_m), meshes


def render_scene_rgb(msg: ReconstructedObjectArray, T_world_camera) -> np.ndarray:
    scene, _ = objects_to_scene(msg)
    world = SimWorld(scene, robot_arm=False)
    rgb = world.render(T_world_camera, with_visibility=False).rgb
    world.close()
    return rgb


def colourise(labels: np.ndarray) -> np.ndarray:
    palette = np.random.default_rng(3).uniform(0.2, 1.0, (int(labels.max()) + 1, 3))
    palette[0] = 0
    return palette[labels]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--objects", type=int, default=8)
    parser.add_argument("--out", default=str(ROOT / "results" / "demo"))
    parser.add_argument("--task", choices=["grasp", "push", "rearrange"], default="grasp")
    parser.add_argument("--ground-truth-masks", action="store_true", help="segmentation passes the sim's masks through")
    parser.add_argument("--method", default=None, help="reconstruction method (default: the node's, 'arm')")
    args = parser.parse_args()
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    summary = {"seed": args.seed, "stages": {}}
    t_start = time.monotonic()
    rclpy.init()
    node = rclpy.create_node("arm_demo")
    observer = Observer(node)
    with Graph(ROOT / "log" / "demo") as graph:
        graph.start("sim", "-p", f"seed:={args.seed}", "-p", f"n_objects:={args.objects}")
        stages = [k for k in ("segmentation", "reconstruction", "planner") if node_available(k)]
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
        summary["stages"] = {
            k: ("running" if k in stages or k == "sim" else "not built")
            for k in ("sim", "segmentation", "reconstruction", "planner")
        }
        print(f"[demo] node graph: {summary['stages']}", flush=True)

        sim_topics = [
            "camera/color/image_raw",
            "camera/depth/image_raw",
            "camera/camera_info",
            "camera/pose",
            "sim/ground_truth/objects",
            "sim/ground_truth/labels",
        ]
        if not observer.wait(sim_topics, 90.0):
            print(f"[demo] the sim published nothing in time: {observer.counts}", file=sys.stderr)
            return 1
        truth = observer.latest["sim/ground_truth/objects"]
        T_world_camera = pose_to_matrix(observer.latest["camera/pose"].pose)
        rgb_before, depth = observer.frame()
        gt_labels = image_to_numpy(observer.latest["sim/ground_truth/labels"])
        summary["objects"] = [{"id": o.id, "visible_fraction": round(o.visible_fraction, 3)} for o in truth.objects]
        summary["camera_K"] = K_from_camera_info(observer.latest["camera/camera_info"]).round(2).tolist()

        seg_labels = None
        if "segmentation" in stages and observer.wait(["arm/segmented_frame"], 120.0):
            seg_labels = image_to_numpy(observer.latest["arm/segmented_frame"].labels)
            summary["segmented_instances"] = int(len(np.unique(seg_labels)) - 1)
        fig, axes = plt.subplots(1, 3, figsize=(15, 4))
        axes[0].imshow(rgb_before)
        axes[0].set_title(f"camera (seed {args.seed}, {len(truth.objects)} objects)")
        axes[1].imshow(np.where(depth > 0, depth, np.nan), cmap="viridis")
        axes[1].set_title("depth (m, noisy)")
        overlay = 0.5 * rgb_before / 255.0 + 0.5 * colourise(seg_labels if seg_labels is not None else gt_labels)
        axes[2].imshow(np.clip(overlay, 0, 1))
        axes[2].set_title("segmentation overlay" if seg_labels is not None else "ground-truth labels (no segmentation)")
        for a in axes:
            a.axis("off")
        fig.tight_layout()
        fig.savefig(out / "camera_segmentation.png", dpi=90)
        plt.close(fig)

        meshes = None
        if "reconstruction" in stages and observer.wait(["arm/meshes"], 180.0):
            meshes = observer.latest["arm/meshes"]
            _, recon = objects_to_scene(meshes)
            _, gt = objects_to_scene(truth)
            errors = []
            for rid, rmesh in recon:
                centre = rmesh.centroid
                gid, gmesh = min(gt, key=lambda g: np.linalg.norm(g[1].centroid - centre))
                errors.append({"id": rid, "matched_truth_id": gid, "chamfer_m": round(chamfer_m(rmesh, gmesh), 4)})
            summary["reconstruction"] = {
                "objects": len(recon),
                "per_object": errors,
                "mean_chamfer_m": float(np.mean([e["chamfer_m"] for e in errors] or [np.nan])),
            }
            side_view = look_at((0.0, -0.9, 0.45), (0.0, 0.0, 0.05))
            fig, axes = plt.subplots(2, 2, figsize=(12, 9))
            for row, (name, camera) in enumerate([("camera view", T_world_camera), ("side view", side_view)]):
                axes[row, 0].imshow(render_scene_rgb(meshes, camera))
                axes[row, 0].set_title(f"reconstruction ({meshes.objects[0].method if meshes.objects else ''}), {name}")
                axes[row, 1].imshow(render_scene_rgb(truth, camera))
                axes[row, 1].set_title(f"ground truth, {name}")
            for a in axes.ravel():
                a.axis("off")
            fig.tight_layout()
            fig.savefig(out / "reconstruction_vs_truth.png", dpi=80)
            plt.close(fig)

        if "planner" in stages and meshes is not None and meshes.objects:
            summary["task"] = run_task(node, observer, meshes, truth, args.task)
            rgb_after = None
            if observer.wait(["camera/color/image_raw"], 20.0, observer.counts.get("camera/color/image_raw", 0) + 2):
                rgb_after, _ = observer.frame()
            if rgb_after is not None:
                fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
                axes[0].imshow(rgb_before)
                axes[0].set_title("before")
                axes[1].imshow(rgb_after)
                axes[1].set_title(f"after {args.task}: success={summary['task'].get('success_in_sim')}")
                for a in axes:
                    a.axis("off")
                fig.tight_layout()
                fig.savefig(out / "before_after.png", dpi=90)
                plt.close(fig)

        rclpy.spin_once(node, timeout_sec=0.5)
        summary["failed_stage"] = first_silent_stage(stages, seg_labels, meshes, summary.get("task"))
        summary["latency"] = observer.diagnostics
        summary["alive_at_end"] = graph.alive()
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


def first_silent_stage(stages, seg_labels, meshes, task) -> str | None:
    """The first running stage whose output never reached the demo (None when all did)."""
    outputs = {"segmentation": seg_labels, "reconstruction": meshes, "planner": task}
    return next((key for key in stages if outputs[key] is None), None)


def run_task(node, observer, meshes, truth, task: str) -> dict:
    """Send one manipulation request for the most visible reconstructed object; judge it in the sim."""
    client = ActionClient(node, Manipulate, "arm/manipulate")
    if not client.wait_for_server(timeout_sec=60.0):
        return {"error": "plan_node action server not available"}
    shoulder = np.array([ROBOT_BASE_XY[0], ROBOT_BASE_XY[1], 0.333])
    reachable = [o for o in meshes.objects if np.linalg.norm(pose_to_matrix(o.pose)[:3, 3] - shoulder) < 0.7]
    target = max(reachable or meshes.objects, key=lambda o: o.visible_fraction)
    goal = Manipulate.Goal(task={"grasp": 0, "push": 1, "rearrange": 2}[task], target_id=target.id)
    if task == "push":
        goal.goal_displacement.x, goal.goal_displacement.y = 0.05, -0.30
    elif task == "rearrange":
        goal.goal_displacement.x, goal.goal_displacement.y = 0.20, 0.20
    T_target = pose_to_matrix(target.pose)
    _, gt = objects_to_scene(truth)
    gt_id, _ = min(gt, key=lambda g: np.linalg.norm(g[1].centroid - T_target[:3, 3]))
    start = pose_to_matrix(observer.latest["sim/ground_truth/poses"].poses[gt_id - 1])[:3, 3]
    t0 = time.monotonic()
    future = client.send_goal_async(goal)
    while not future.done():
        rclpy.spin_once(node, timeout_sec=0.05)
    handle = future.result()
    if not handle.accepted:
        return {"error": "goal rejected"}
    result_future = handle.get_result_async()
    while not result_future.done() and time.monotonic() - t0 < 400:
        rclpy.spin_once(node, timeout_sec=0.05)
    if not result_future.done():
        return {"error": "planning timed out"}
    result = result_future.result().result
    plan_s = time.monotonic() - t0
    duration = 0.0
    if result.trajectory.points:
        last = result.trajectory.points[-1].time_from_start
        duration = last.sec + 1e-9 * last.nanosec
    # the sim executes the published trajectory in simulated time (50 joint states per simulated second)
    wanted_states = observer.counts.get("joint_states", 0) + int(duration * 50) + 50
    observer.wait(["joint_states"], duration * 4 + 20.0, wanted_states)
    observer.wait(["sim/ground_truth/poses"], 10.0, observer.counts.get("sim/ground_truth/poses", 0) + 2)
    end = pose_to_matrix(observer.latest["sim/ground_truth/poses"].poses[gt_id - 1])[:3, 3]
    moved = end - start
    if task == "grasp":
        success, error = bool(moved[2] >= 0.05), max(0.0, 0.05 - float(moved[2]))
    else:
        wanted = np.array([goal.goal_displacement.x, goal.goal_displacement.y])
        error = float(np.linalg.norm(moved[:2] - wanted))
        success = error <= 0.025
    return {
        "task": task,
        "target_id": int(target.id),
        "truth_id": int(gt_id),
        "planned_success": bool(result.success),
        "message": result.message,
        "predicted_error_m": round(float(result.final_error_m), 4),
        "planning_s": round(plan_s, 1),
        "trajectory_s": round(duration, 2),
        "target_displacement_m": np.round(moved, 4).tolist(),
        "success_in_sim": success,
        "error_in_sim_m": round(error, 4),
    }


if __name__ == "__main__":
    raise SystemExit(main())
