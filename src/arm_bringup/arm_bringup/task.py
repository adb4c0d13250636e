"""The demo's manipulation request. Candidates are the reachable reconstructed objects, most visible
first (for a grasp, those the open gripper can span; a rearrange prefers them). Up to DRY_RUNS of them
are planned without executing (plan_only goals); the first whose plan meets the task in the planner's
twin is the target, and the same goal without plan_only executes that very plan (plan_node keeps it),
judged in the simulator by how the true object moved. Where no object suits the task, no goal is sent
and the reason is reported."""

import time

import numpy as np
import rclpy
from rclpy.action import ActionClient

from arm_bringup.scenes import objects_to_scene
from arm_interfaces.action import Manipulate
from arm_planner.session import reach_problem
from arm_planner.tasks.base import narrowest_horizontal_width_m
from arm_ros.conversions.meshes import msg_to_mesh
from arm_ros.conversions.poses import pose_to_matrix
from arm_sim.robot import FINGER_GAP_OPEN_M
from arm_sim.world import ROBOT_BASE_XY

# Side room a grasp leaves between the object and each finger, metres.
GRASP_SIDE_ROOM_M = 0.005
# Candidates, most visible first, planned without executing before one is chosen.
DRY_RUNS = 3


def rank_targets(objects, task: str, table_height_m: float = 0.0):
    """(candidates, why): the objects the planner's reach allows (arm_planner.session.reach_problem),
    most visible first. A grasp needs one whose narrowest horizontal width, with GRASP_SIDE_ROOM_M on
    each side, fits between the open fingers; a rearrange prefers one (a wider one is pushed). No
    candidates, with the reason, when no object suits the task."""
    problems = {o.id: reach_problem(pose_to_matrix(o.pose)[:3, 3], ROBOT_BASE_XY, table_height_m) for o in objects}
    candidates = [o for o in objects if problems[o.id] is None]
    if not candidates:
        nearest = next(iter(sorted(problems.values(), key=str)), "no objects")
        return [], f"no reconstructed object within the arm's reach ({len(objects)} seen; e.g. {nearest})"
    why = f"{len(candidates)} object(s) within reach"
    if task in ("grasp", "rearrange"):
        gap = FINGER_GAP_OPEN_M - 2 * GRASP_SIDE_ROOM_M
        fitting = [o for o in candidates if narrowest_horizontal_width_m(msg_to_mesh(o.mesh)[0]) <= gap]
        if fitting:
            candidates, why = fitting, why + f", {len(fitting)} fitting between the open fingers ({gap * 100:.1f} cm)"
        elif task == "grasp":
            return [], f"none of the {len(candidates)} object(s) within reach fits between the open fingers"
        else:
            why += "; none fits between the open fingers, so it is pushed"
    return sorted(candidates, key=lambda o: -o.visible_fraction), why


def task_goal(task: str, target, meshes, plan_only: bool = False):
    goal = Manipulate.Goal(
        task={"grasp": 0, "push": 1, "rearrange": 2}[task],
        target_id=target.id,
        meshes_stamp=meshes.header.stamp,
        plan_only=plan_only,
    )
    if task == "push":
        goal.goal_displacement.x, goal.goal_displacement.y = 0.05, -0.30
    elif task == "rearrange":
        goal.goal_displacement.x, goal.goal_displacement.y = 0.20, 0.20
    return goal


def send_and_wait(node, client, goal, timeout_s: float = 400.0):
    """The goal's result, or None when it was rejected or timed out."""
    t0 = time.monotonic()
    future = client.send_goal_async(goal)
    while not future.done():
        rclpy.spin_once(node, timeout_sec=0.05)
    handle = future.result()
    if not handle.accepted:
        return None
    result_future = handle.get_result_async()
    while not result_future.done() and time.monotonic() - t0 < timeout_s:
        rclpy.spin_once(node, timeout_sec=0.05)
    return result_future.result().result if result_future.done() else None


def choose_by_dry_runs(node, client, meshes, task: str, candidates: list):
    """(target, why, dry runs): the first of up to DRY_RUNS candidates whose plan-only request met the
    task in the planner's twin; the most visible candidate when none did."""
    runs = []
    for candidate in candidates[:DRY_RUNS]:
        result = send_and_wait(node, client, task_goal(task, candidate, meshes, plan_only=True))
        met = bool(result is not None and result.success)
        runs.append({"id": int(candidate.id), "met_in_twin": met, "message": result.message if result else "no result"})
        if met:
            tried = f"{len(runs)} of {min(len(candidates), DRY_RUNS)} tried"
            seen = f"visible {candidate.visible_fraction:.0%}"
            return candidate, f"object {candidate.id} ({seen}): its dry run met the task in the twin ({tried})", runs
    target = candidates[0]
    why = f"object {target.id}, the most visible: no dry run of the {len(runs)} tried met the task in the twin"
    return target, why, runs


def run_task(node, observer, meshes, truth, task: str) -> dict:
    """Choose a target by dry runs in the planner's twin, send the manipulation request and judge it in
    the sim by how the true object moved."""
    client = ActionClient(node, Manipulate, "arm/manipulate")
    if not client.wait_for_server(timeout_sec=60.0):
        return {"error": "plan_node action server not available"}
    candidates, why = rank_targets(meshes.objects, task, meshes.table_height_m)
    if not candidates:
        print(f"[demo] {task}: no target: {why}", flush=True)
        return {"task": task, "target_id": None, "why": why, "success_in_sim": None}
    target, chosen, dry_runs = choose_by_dry_runs(node, client, meshes, task, candidates)
    why = f"{why}; {chosen}"
    print(f"[demo] {task} target: {why}", flush=True)
    goal = task_goal(task, target, meshes)
    T_target = pose_to_matrix(target.pose)
    _, gt = objects_to_scene(truth)
    gt_id, _ = min(gt, key=lambda g: np.linalg.norm(g[1].centroid - T_target[:3, 3]))
    start = pose_to_matrix(observer.latest["sim/ground_truth/poses"].poses[gt_id - 1])[:3, 3]
    t0 = time.monotonic()
    result = send_and_wait(node, client, goal)
    if result is None:
        return {"error": "goal rejected or planning timed out"}
    plan_s = time.monotonic() - t0  # planning and, with ros2_control, the execution
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
        "why": why,
        "dry_runs": dry_runs,
        "truth_id": int(gt_id),
        "planned_success": bool(result.success),
        "message": result.message,
        "predicted_error_m": round(float(result.final_error_m), 4),
        "controller_error_code": int(result.controller_error_code),
        "controller_message": result.controller_message,
        "observed_displacement_m": (
            np.round(
                [result.observed_displacement.x, result.observed_displacement.y, result.observed_displacement.z], 4
            ).tolist()
            if result.displacement_observed
            else None
        ),
        "planning_s": round(plan_s, 1),
        "trajectory_s": round(duration, 2),
        "target_displacement_m": np.round(moved, 4).tolist(),
        "success_in_sim": success,
        "error_in_sim_m": round(error, 4),
    }
