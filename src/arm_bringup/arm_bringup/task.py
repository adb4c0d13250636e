"""The demo's manipulation request. Candidates are the reachable reconstructed objects, most visible
first (for a grasp, those the open gripper can span; a rearrange prefers them). Up to DRY_RUNS
plan-only goals plan them in turn without executing, each again while goals remain; plan_node replays
each plan that met the task in perturbed twins (objects moved by millimetres, friction, mass, latency,
joint offsets). The first candidate whose plan met the task in the planner's twin, held it and met it
in at least ROBUST_SHARE of its perturbed twins is the target; else the held plan met in the most
perturbed twins; else the first whose latest dry run met the task (in the demo benchmark's runs a plan
that held the task lifted its target in the simulator in 55 of 75 attempts, one that met it only at
the end of its step budget in 12 of 23). The same goal without plan_only executes that very plan
(plan_node keeps it), judged in the simulator by how the true object moved. A grasp the robot finds
empty, or never closed, sends the arm home and is tried again on the next view, up to ATTEMPTS times.
Where no object suits the task, or no dry run meets it, nothing is executed and the reason is
reported."""

import time

import numpy as np
import rclpy
from control_msgs.action import FollowJointTrajectory
from rclpy.action import ActionClient

from arm_bringup.scenes import objects_to_scene
from arm_interfaces.action import Manipulate
from arm_planner.messages import trajectory_msg
from arm_planner.session import reach_problem
from arm_planner.tasks import GRASP_LIFT_M
from arm_planner.tasks.base import narrowest_horizontal_width_m
from arm_ros.conversions.images import image_to_numpy
from arm_ros.conversions.meshes import msg_to_mesh
from arm_ros.conversions.poses import pose_to_matrix
from arm_sim.robot import FINGER_GAP_OPEN_M, FINGER_JOINT_NAMES, GRIPPER_OPEN_M, HOME_Q, JOINT_NAMES
from arm_sim.world import ROBOT_BASE_XY

# Side room a grasp leaves between the object and each finger, metres.
GRASP_SIDE_ROOM_M = 0.005
# Plan-only goals over the candidates, most visible first, before one is chosen (a dry run takes about
# 4 s; in the demo's scenes about half meet the task in the twin).
DRY_RUNS = 10
# A held plan met in at least this share of its perturbed twins (plan_node's replays) ends the dry runs.
ROBUST_SHARE = 0.8
# Attempts at a grasp: one the robot finds holds nothing (grasp_held) is tried again on a new view.
ATTEMPTS = 3
# A finger closed to this or less (m) holds nothing (a lamp held by its 3 mm stem reads 1.6 mm).
EMPTY_GRASP_M = 0.001
# A finger within this of fully open (m) never closed: the widest target the demo grasps (7.2 cm)
# leaves it 5 mm short of open.
OPEN_GRASP_M = 0.002
# Before the scene is observed again the arm goes back to its home pose, out of the camera's way.
HOME_MOTION_S = 2.5
ARM_CONTROLLER_ACTION = "arm_controller/follow_joint_trajectory"
# Objects of a new view within this of a target tried before (m) are that object.
SAME_OBJECT_M = 0.05
MESHES_TOPIC = "arm/meshes"
NEW_MESHES_TIMEOUT_S = 60.0


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


def _replays(result) -> tuple[int, int]:
    """(perturbed twins met, replayed) of a dry run's result (0, 0: not replayed)."""
    return int(result.perturbed_twins_met), int(result.perturbed_twins)


def _robust(run: dict) -> bool:
    met, twins = run["perturbed_twins"]
    return run["held_in_twin"] and twins > 0 and met >= ROBUST_SHARE * twins


def choose_by_dry_runs(candidates: list, dry_run):
    """(target or None, why, dry runs): up to DRY_RUNS plan-only requests over the first DRY_RUNS
    candidates, each once in turn and then, while requests remain, again in the same order (MPPI
    samples anew each time, so a candidate whose plan did not meet the task, or met it without
    holding it, may the next time). plan_node replays each plan that met the task in perturbed twins.
    The target is the first candidate whose plan met the task in the planner's twin, held it
    (held_in_twin) and met it in at least ROBUST_SHARE of its perturbed twins; where none did, of the
    candidates whose latest dry run held, the one met in the most perturbed twins (the first of
    equals); where none held, the first whose latest dry run met the task at all (plan_node keeps the
    latest plan of each request, and executes it as it was planned); None when none did (a plan
    predicted to fail is not executed). dry_run(candidate): the plan-only goal's Manipulate.Result,
    or None."""
    pool = candidates[:DRY_RUNS]
    runs, latest = [], {}
    for turn in range(DRY_RUNS if pool else 0):
        candidate = pool[turn % len(pool)]
        result = dry_run(candidate)
        met = bool(result is not None and result.success)
        run = {
            "id": int(candidate.id),
            "met_in_twin": met,
            "held_in_twin": bool(met and result.held_in_twin),
            "perturbed_twins": _replays(result) if met else (0, 0),
            "message": result.message if result else "no result",
        }
        runs.append(run)
        latest[candidate.id] = run
        if _robust(run):
            break
    tried = f"{len(runs)} dry run(s) of {len(pool)} candidate(s)"
    held = [c for c in pool if c.id in latest and latest[c.id]["held_in_twin"]]
    if held:
        target = max(held, key=lambda c: latest[c.id]["perturbed_twins"][0])
        met, twins = latest[target.id]["perturbed_twins"]
        how = f"met the task in the twin and held it, and met it in {met} of {twins} perturbed twins"
    else:
        target = next((c for c in pool if c.id in latest and latest[c.id]["met_in_twin"]), None)
        how = "met the task in the twin at the end of its step budget (none held it)"
    if target is None:
        return None, f"no dry run of the {len(runs)} tried met the task in the twin ({tried})", runs
    seen = f"visible {target.visible_fraction:.0%}"
    return target, f"object {target.id} ({seen}): its latest dry run {how} ({tried})", runs


def finger_opening_m(joint_states) -> float | None:
    """The gripper finger's position (m, 0 = closed) in a JointState, or None without it."""
    names = list(joint_states.name)
    if FINGER_JOINT_NAMES[0] not in names:
        return None
    return float(joint_states.position[names.index(FINGER_JOINT_NAMES[0])])


def grasp_held(task: str, finger_m: float | None) -> bool:
    """The robot's own verdict on a grasp: its fingers closed, and not on nothing (open to within
    OPEN_GRASP_M of GRIPPER_OPEN_M, they never closed on the target). (The view after the motion is no
    judge: with the held target masked as part of the arm, the object plan_node finds nearest its last
    centre is a neighbour that did not move.)"""
    return task == "grasp" and finger_m is not None and EMPTY_GRASP_M < finger_m < GRIPPER_OPEN_M - OPEN_GRASP_M


def truth_positions(poses) -> np.ndarray:
    """[N, 3] world positions (m) of the true objects (sim/ground_truth/poses; id i at row i - 1)."""
    return np.array([pose_to_matrix(p)[:3, 3] for p in poses.poses]).reshape(-1, 3)


def truth_of_target(target, observer, meshes, truth) -> int:
    """The ground-truth id of a reconstructed target: the true object under most of its pixels in the
    segmented frame the meshes were built from, else the one whose centre is nearest its centre."""
    segmented = observer.segmented_frame_for(meshes.header)
    labels = observer.latest.get("sim/ground_truth/labels")
    if segmented is not None and labels is not None:
        true_labels, instances = image_to_numpy(labels), image_to_numpy(segmented.labels)
        true_ids = true_labels[instances == target.id] if true_labels.shape == instances.shape else []
        true_ids = np.asarray(true_ids, dtype=np.int64)
        true_ids = true_ids[true_ids > 0]
        if true_ids.size:
            return int(np.bincount(true_ids).argmax())
    centre = pose_to_matrix(target.pose)[:3, 3]
    centres = truth_centres(truth, observer.latest["sim/ground_truth/poses"])
    return min(centres, key=lambda g: np.linalg.norm(g[1] - centre))[0]


def truth_centres(truth, poses) -> list[tuple[int, np.ndarray]]:
    """(ground-truth id, world centre m) of every true object at its current pose (sim/ground_truth/poses)."""
    _, placed = objects_to_scene(truth)
    centres = []
    for (gt_id, mesh), obj in zip(placed, truth.objects, strict=True):
        T_now_then = pose_to_matrix(poses.poses[gt_id - 1]) @ np.linalg.inv(pose_to_matrix(obj.pose))
        centres.append((gt_id, T_now_then[:3, :3] @ mesh.centroid + T_now_then[:3, 3]))
    return centres


def far_from(objects, points_m, distance_m: float) -> list:
    """The objects whose centre is more than distance_m from every point (world, m)."""
    return [
        o for o in objects
        if all(np.linalg.norm(pose_to_matrix(o.pose)[:3, 3] - p) > distance_m for p in points_m)
    ]  # fmt: skip


def attempt_task(node, client, observer, meshes, truth, task: str, tried_m: list) -> dict:
    """One attempt: choose a target by dry runs among the objects not tried before (tried_m: their
    centres), execute its plan and judge it in the sim by how the true object moved; `held` is the
    robot's own verdict on a grasp (grasp_held)."""
    objects = far_from(meshes.objects, tried_m, SAME_OBJECT_M)
    candidates, why = rank_targets(objects, task, meshes.table_height_m)
    if len(objects) < len(meshes.objects):
        why = f"{len(meshes.objects) - len(objects)} object(s) tried before left out; {why}"
    if not candidates:
        return {"task": task, "target_id": None, "why": why, "success_in_sim": None}
    target, chosen, dry_runs = choose_by_dry_runs(
        candidates, lambda c: send_and_wait(node, client, task_goal(task, c, meshes, plan_only=True))
    )
    why = f"{why}; {chosen}"
    if target is None:
        return {"task": task, "target_id": None, "why": why, "dry_runs": dry_runs, "success_in_sim": None}
    print(f"[demo] {task} target: {why}", flush=True)
    goal = task_goal(task, target, meshes)
    T_target = pose_to_matrix(target.pose)
    poses_topic = "sim/ground_truth/poses"
    gt_id = truth_of_target(target, observer, meshes, truth)
    starts = truth_positions(observer.latest[poses_topic])
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
    observer.wait([poses_topic], 10.0, observer.counts.get(poses_topic, 0) + 2)
    ends = truth_positions(observer.latest[poses_topic])
    moved = ends[gt_id - 1] - starts[gt_id - 1]
    lifted = [i + 1 for i in np.flatnonzero(ends[:, 2] - starts[:, 2] >= GRASP_LIFT_M)]
    if task == "grasp":
        success, error = bool(moved[2] >= GRASP_LIFT_M), max(0.0, GRASP_LIFT_M - float(moved[2]))
    else:
        wanted = np.array([goal.goal_displacement.x, goal.goal_displacement.y])
        error = float(np.linalg.norm(moved[:2] - wanted))
        success = error <= 0.025
    opening = finger_opening_m(observer.latest["joint_states"])
    observed = (
        [result.observed_displacement.x, result.observed_displacement.y, result.observed_displacement.z]
        if result.displacement_observed
        else None
    )
    return {
        "task": task,
        "target_id": int(target.id),
        "target_centre_m": np.round(T_target[:3, 3], 4).tolist(),
        "why": why,
        "dry_runs": dry_runs,
        "truth_id": int(gt_id),
        "planned_success": bool(result.success),
        "message": result.message,
        "predicted_error_m": round(float(result.final_error_m), 4),
        "controller_error_code": int(result.controller_error_code),
        "controller_message": result.controller_message,
        "observed_displacement_m": None if observed is None else np.round(observed, 4).tolist(),
        "finger_opening_m": None if opening is None else round(opening, 4),
        "held": grasp_held(task, opening),
        "planning_s": round(plan_s, 1),
        "trajectory_s": round(duration, 2),
        "target_displacement_m": np.round(moved, 4).tolist(),
        "truth_ids_lifted": [int(i) for i in lifted],
        "success_in_sim": success,
        "error_in_sim_m": round(error, 4),
    }


def go_home(node, client) -> str:
    """Move the arm to its home pose through the arm controller; how that ended."""
    if not client.wait_for_server(timeout_sec=10.0):
        return f"{ARM_CONTROLLER_ACTION} not available"
    goal = FollowJointTrajectory.Goal(trajectory=trajectory_msg(JOINT_NAMES, [HOME_MOTION_S], [HOME_Q]))
    result = send_and_wait(node, client, goal, timeout_s=60.0)
    return "no result" if result is None else f"error code {result.error_code}: {result.error_string}"


def run_task(node, observer, meshes, truth, task: str) -> dict:
    """Up to ATTEMPTS attempts (attempt_task): after a grasp that holds nothing (grasp_held) the arm
    goes home and the task is tried again on the next reconstruction of the scene, leaving out the
    objects tried. The last attempt's report, with every attempt under "attempts"."""
    client = ActionClient(node, Manipulate, "arm/manipulate")
    if not client.wait_for_server(timeout_sec=60.0):
        return {"error": "plan_node action server not available"}
    home_client = ActionClient(node, FollowJointTrajectory, ARM_CONTROLLER_ACTION)
    attempts, tried_m = [], []
    while True:
        attempt = attempt_task(node, client, observer, meshes, truth, task, tried_m)
        attempts.append(attempt)
        if attempt.get("target_id") is None:
            print(f"[demo] {task}: no target: {attempt.get('why') or attempt.get('error')}", flush=True)
        if attempt.get("target_id") is None or task != "grasp" or attempt["held"] or len(attempts) == ATTEMPTS:
            break
        print(f"[demo] attempt {len(attempts)}: the grasp holds nothing; observing the scene again", flush=True)
        tried_m.append(np.asarray(attempt["target_centre_m"]))
        attempt["home"] = go_home(node, home_client)
        meshes = observer.newer(MESHES_TOPIC, observer.latest["joint_states"].header.stamp, NEW_MESHES_TIMEOUT_S)
        if meshes is None:
            break
    report = dict(next((a for a in reversed(attempts) if a.get("target_id") is not None), attempts[-1]))
    report["attempts"] = attempts
    report["done_at_first_attempt"] = bool(attempts[0].get("success_in_sim"))
    return report
