"""The planner in the running graph: real-time factor under load (results/perf/summary.json, bench_perf).

Starts sim_node (640x480 at its default rate, n_objects 10), segmentation_node, reconstruction_node and
plan_node as processes on the sim's time, waits for /arm/meshes, then sends /arm/manipulate goals
(grasp, push, rearrange, each on another reachable object) and records per goal: the user's wait (goal
sent -> result, wall s), the planned motion's duration, plan_node's /diagnostics (realtime_factor,
MPPI step times) and the CPU seconds every node process used while the goal was served. The first
goal, a grasp, is served with segmentation and reconstruction stopped (SIGSTOP) to tell CPU
contention from the rest; the others with the whole graph running.
"""

from __future__ import annotations

import json
import os
import pathlib
import signal
import time

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.action import ActionClient

from arm_benchmarks.stats import median
from arm_interfaces.action import Manipulate
from arm_interfaces.msg import ReconstructedObjectArray
from arm_ros.common import latched_qos
from arm_ros.conversions.poses import pose_to_matrix
from arm_ros.processes import NodeProcess

SHOULDER_WORLD_M = np.array([-0.55, 0.0, 0.333])
# task -> (Manipulate task number, goal displacement m); the rearrange goal lies towards the robot, in reach
TASKS = {"grasp": (0, (0.0, 0.0, 0.0)), "push": (1, (0.05, -0.30, 0.0)), "rearrange": (2, (-0.15, -0.10, 0.0))}
DIAG_KEYS = (
    "realtime_factor",
    "last_plan_s",
    "last_motion_s",
    "mppi_steps_last",
    "mppi_step_ms_last",
    "mppi_step_ms_median",
    "mppi_step_ms_p90",
    "mppi_step_cpu_ms_median",
    "mppi_paths_median",
    "mppi_paths_min",
    "stream_parts",
    "stream_stall_s",
)


def cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process so far (nan once it is gone)."""
    try:
        fields = pathlib.Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return float("nan")
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class GraphClient:
    def __init__(self, node):
        self.node = node
        self.meshes = None
        self.planner_diag: dict[str, str] = {}
        self.diag_count = 0
        node.create_subscription(ReconstructedObjectArray, "arm/meshes", self._meshes, latched_qos())
        node.create_subscription(DiagnosticArray, "diagnostics", self._diag, 50)
        self.client = ActionClient(node, Manipulate, "arm/manipulate")

    def _meshes(self, msg):
        self.meshes = msg

    def _diag(self, msg):
        for status in msg.status:
            if status.name.startswith("plan_node"):
                self.planner_diag = {kv.key: kv.value for kv in status.values}
                self.diag_count += 1

    def spin_until(self, done, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            rclpy.spin_once(self.node, timeout_sec=0.05)
            if done():
                return True
        return False

    def goal(self, task: str, target_id: int, timeout_s: float = 600.0) -> dict:
        number, displacement = TASKS[task]
        goal = Manipulate.Goal(task=number, target_id=int(target_id))
        goal.goal_displacement.x, goal.goal_displacement.y, goal.goal_displacement.z = displacement
        t0 = time.monotonic()
        future = self.client.send_goal_async(goal)
        self.spin_until(future.done, 30.0)
        if not future.done() or not future.result().accepted:
            return {"error": "goal not accepted"}
        result_future = future.result().get_result_async()
        if not self.spin_until(result_future.done, timeout_s):
            return {"error": "no result in time"}
        wait_s = time.monotonic() - t0
        result = result_future.result().result
        points = result.trajectory.points
        motion_s = points[-1].time_from_start.sec + 1e-9 * points[-1].time_from_start.nanosec if points else 0.0
        return {
            "wait_s": wait_s,
            "motion_s": motion_s,
            "planned_success": bool(result.success),
            "message": result.message,
        }

    def diagnostics_after(self) -> dict:
        """plan_node's diagnostics published after now (it publishes once a second)."""
        count = self.diag_count
        self.spin_until(lambda: self.diag_count >= count + 2, 10.0)
        values = {}
        for key in DIAG_KEYS:
            try:
                values[key] = float(self.planner_diag[key])
            except (KeyError, ValueError):
                values[key] = float("nan")
        return values


def reachable_targets(meshes) -> list[int]:
    """Object ids, nearest to the arm's shoulder first (plan_node refuses those out of reach)."""
    distance_m = {o.id: np.linalg.norm(pose_to_matrix(o.pose)[:3, 3] - SHOULDER_WORLD_M) for o in meshes.objects}
    return sorted(distance_m, key=distance_m.get)


def _serve(client: GraphClient, task: str, targets: list[int], processes: dict) -> dict:
    """One goal on the first target plan_node accepts; CPU seconds per process while it was served."""
    failures = {}
    for target in list(targets):
        before = {k: cpu_s(p.pid) for k, p in processes.items()}
        row = client.goal(task, target)
        for _ in range(20):  # a freshly started plan_node may not have heard the sim yet
            if not row.get("message", "").startswith(("no joint states", "no reconstructed objects")):
                break
            client.spin_until(lambda: False, 1.0)
            row = client.goal(task, target)
        if "error" not in row and row["motion_s"] > 0:
            targets.remove(target)
            row |= {"task": task, "target_id": target, "load_average": os.getloadavg()[0]}
            row["cpu_s"] = {k: round(cpu_s(p.pid) - before[k], 2) for k, p in processes.items()}
            row |= client.diagnostics_after()
            # let the motion finish before the next goal (it started while planning; the sim runs ~real time)
            client.spin_until(lambda: False, max(0.0, row["motion_s"] - row["wait_s"] + row["stream_stall_s"]) + 2.0)
            return row
        failures[target] = row.get("error") or row.get("message")
    return {"task": task, "error": "no reachable target was planned for", "failures": failures}


def run_seed(
    seed: int,
    n_objects: int,
    log_dir: pathlib.Path,
    client: GraphClient,
    planner_params: dict | None = None,
    reconstruction_params: dict | None = None,
) -> dict:
    sim_time = {"use_sim_time": True}
    processes = {
        # the sim keeps rendering during goals (its default pauses): the load stays that of earlier runs
        "sim": NodeProcess(
            "sim",
            log_dir / "sim.log",
            ros_args=("-p", f"seed:={seed}", "-p", f"n_objects:={n_objects}", "-p", "pause_during_goals:=false"),
        )
    }
    processes["segmentation"] = NodeProcess(
        "segmentation", log_dir / "segmentation.log", params=sim_time | {"image_reliability": "reliable"}
    )
    processes["reconstruction"] = NodeProcess(
        "reconstruction", log_dir / "reconstruction.log", params=sim_time | (reconstruction_params or {})
    )
    # the trajectory on the topic: a goal's result then comes when planning ends, which this times
    planner = sim_time | {"controller_interface": "topic"} | (planner_params or {})
    processes["planner"] = NodeProcess("planner", log_dir / "planner.log", params=planner)
    rows = []
    try:
        client.meshes, client.planner_diag = None, {}
        if not client.spin_until(lambda: client.meshes is not None and client.meshes.objects, 400.0):
            return {"seed": seed, "error": "no /arm/meshes in time"}
        # the first array may miss objects still being reconstructed: wait a while for (nearly) all
        client.spin_until(lambda: len(client.meshes.objects) >= n_objects - 1, 90.0)
        client.client.wait_for_server(timeout_sec=60.0)
        if not client.spin_until(lambda: int(client.planner_diag.get("twin_objects", 0)) > 0, 120.0):
            return {"seed": seed, "error": "plan_node got no /arm/meshes in time"}
        objects = len(client.meshes.objects)
        targets = reachable_targets(client.meshes)
        upstream = [processes["segmentation"], processes["reconstruction"]]
        for process in upstream:
            process.process.send_signal(signal.SIGSTOP)
        try:
            rows.append(_serve(client, "grasp", targets, processes) | {"upstream": "stopped"})
        finally:
            for process in upstream:
                process.process.send_signal(signal.SIGCONT)
        for task in TASKS:
            rows.append(_serve(client, task, targets, processes) | {"upstream": "running"})
    finally:
        for process in processes.values():
            process.stop()
    return {"seed": seed, "objects": objects, "goals": rows}


def _summary(runs: list[dict]) -> dict:
    loaded = [g for r in runs for g in r.get("goals", []) if g.get("upstream") == "running" and "error" not in g]
    quiet = [g for r in runs for g in r.get("goals", []) if g.get("upstream") == "stopped" and "error" not in g]
    figures = {"planner_graph_runs": runs}
    if loaded:
        figures |= {
            "planner_graph_realtime_factor_median": median([g["realtime_factor"] for g in loaded]),
            "planner_graph_realtime_factor_max": max(g["realtime_factor"] for g in loaded),
            "planner_graph_step_ms_median": median([g["mppi_step_ms_median"] for g in loaded]),
            "planner_graph_step_cpu_ms_median": median([g["mppi_step_cpu_ms_median"] for g in loaded]),
            "planner_graph_wait_over_motion_median": median([g["wait_s"] / g["motion_s"] for g in loaded]),
        }
    if quiet:
        figures |= {
            "planner_graph_upstream_stopped_realtime_factor_median": median([g["realtime_factor"] for g in quiet]),
            "planner_graph_upstream_stopped_step_ms_median": median([g["mppi_step_ms_median"] for g in quiet]),
        }
    return figures


def measure(
    seeds=(7, 3), n_objects: int = 10, planner_params: dict | None = None, reconstruction_params: dict | None = None
) -> dict:
    """planner_params, reconstruction_params: node parameters other than their defaults (for comparisons)."""
    root = pathlib.Path(os.environ.get("ARM_ROOT") or pathlib.Path.cwd())
    rclpy.init()
    node = rclpy.create_node("perf_planner_graph")
    client = GraphClient(node)
    runs = []
    try:
        for seed in seeds:
            log_dir = root / "log" / "perf_planner_graph" / f"seed{seed}"
            runs.append(run_seed(seed, n_objects, log_dir, client, planner_params, reconstruction_params))
            print(json.dumps(runs[-1]), flush=True)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    figures = _summary(runs)
    figures["planner_graph_config"] = (
        f"sim_node 640x480 n_objects {n_objects} + segmentation + reconstruction + plan_node "
        f"({planner_params or 'defaults'}, stream on; reconstruction {reconstruction_params or 'defaults'}), "
        f"seeds {list(seeds)}, {os.cpu_count()} cores; first grasp "
        "with segmentation/reconstruction stopped"
    )
    return figures
