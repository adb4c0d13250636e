"""plan_node: malformed and extreme inputs and what the node must do with them."""

from __future__ import annotations

import time

import numpy as np
import trimesh
from rclpy.action import ActionClient
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from arm_benchmarks.robustness.cases.common import finish_report
from arm_benchmarks.robustness.messages import joint_state_msg
from arm_benchmarks.robustness.validators import (
    trajectory_problems,
)
from arm_interfaces.action import Manipulate
from arm_interfaces.msg import ReconstructedObject, ReconstructedObjectArray
from arm_ros.common import latched_qos
from arm_ros.conversions.meshes import mesh_to_msg
from arm_ros.conversions.poses import matrix_to_pose
from arm_sim import robot


def _box_object(object_id, centre, extents=(0.05, 0.05, 0.08)):
    box = trimesh.creation.box(extents=extents)
    T = np.eye(4)
    T[:3, 3] = centre
    return ReconstructedObject(
        id=object_id,
        pose=matrix_to_pose(T),
        mesh=mesh_to_msg(box.vertices, box.faces),
        visible_fraction=1.0,
        method="robustness",
    )


def _mesh_case(mutate, n_extra: int = 0):
    """An array with a good box (id 1) and object 2 changed by mutate (None: a second good box)."""

    def build():
        array = ReconstructedObjectArray(table_height_m=0.0)
        array.header.frame_id = "world"
        array.objects = [_box_object(1, (0.0, 0.0, 0.04)), _box_object(2, (0.0, 0.12, 0.04))]
        for k in range(n_extra):  # a 7 x 6 grid of small boxes, 6 cm apart, in front of the robot
            x, y = divmod(k, 6)
            array.objects.append(
                _box_object(3 + k, (0.1 + 0.06 * x, -0.3 + 0.06 * y + 0.06 * (y >= 3), 0.025), (0.03, 0.03, 0.05))
            )
        if mutate is not None:
            mutate(array)
        return array

    return build


def _object2(fn):
    def mutate(array):
        fn(array.objects[1])

    return mutate


def _nan_vertex(obj):
    obj.mesh.vertices[0].x = float("nan")


def _bad_index(obj):
    obj.mesh.triangles[0].vertex_indices[2] = 100000


def _empty_mesh(obj):
    obj.mesh.vertices, obj.mesh.triangles, obj.convex_parts = [], [], []


def _flat_mesh(obj):
    plane = trimesh.creation.box(extents=(0.05, 0.05, 0.08))
    vertices = plane.vertices.copy()
    vertices[:, 2] = 0.0
    obj.mesh = mesh_to_msg(vertices, plane.faces)


def _one_triangle(obj):
    obj.mesh = mesh_to_msg(np.array([[0, 0, 0], [0.05, 0, 0], [0, 0.05, 0]], float), np.array([[0, 1, 2]]))


def _huge(obj):
    box = trimesh.creation.box(extents=(1e6, 1e6, 1e6))
    obj.mesh = mesh_to_msg(box.vertices, box.faces)


def _pose_nan(obj):
    obj.pose.position.z = float("nan")


def _pose_zero_quaternion(obj):
    obj.pose.orientation.w = 0.0


def _table_nan(array):
    array.table_height_m = float("nan")


def _duplicate_ids(array):
    array.objects[1].id = 1


MESH_CASES = [
    ("NaN vertex", _object2(_nan_vertex), "reject"),
    ("triangle index out of range", _object2(_bad_index), "reject"),
    ("empty mesh, no parts", _object2(_empty_mesh), "reject"),
    ("flat (zero-volume) mesh", _object2(_flat_mesh), "valid"),
    ("single triangle", _object2(_one_triangle), "valid"),
    ("1e6 m box", _object2(_huge), "reject"),
    ("pose NaN", _object2(_pose_nan), "reject"),
    ("pose zero quaternion", _object2(_pose_zero_quaternion), "reject"),
    ("table height NaN", _table_nan, "reject"),
    ("duplicate object ids", _duplicate_ids, "valid"),
]


def run_planner_bad_inputs(probe, process, goal_timeout_s: float = 120.0, crowded_objects: int = 40) -> dict:
    """Degenerate meshes, unknown targets and tasks, bad joint states and goals, then a valid goal."""
    node = "plan_node"
    meshes = probe.publisher(ReconstructedObjectArray, "arm/meshes", latched_qos())
    joints = probe.publisher(JointState, "joint_states", 10)
    trajectories = probe.record(JointTrajectory, "arm/joint_trajectory", 10)
    probe.watch_diagnostics()
    joint_msg = {"msg": joint_state_msg()}
    probe.node.create_timer(0.1, lambda: joints.publish(joint_msg["msg"]))
    action = ActionClient(probe.node, Manipulate, "arm/manipulate")
    ready = action.wait_for_server(timeout_sec=60.0)

    def goal(
        task=Manipulate.Goal.TASK_GRASP, target_id=1, displacement=(0.0, 0.0, 0.0), tolerance_m=0.0, meshes_stamp_s=0
    ):
        started = time.monotonic()
        g = Manipulate.Goal(task=task, target_id=target_id, tolerance_m=tolerance_m)
        g.meshes_stamp.sec = meshes_stamp_s
        g.goal_displacement.x, g.goal_displacement.y, g.goal_displacement.z = displacement
        handle_future = probe.in_executor(lambda: action.send_goal_async(g))
        if not probe.wait_until(lambda: handle_future.done() or not process.alive(), 30.0) or not process.alive():
            return {"answered": False, "message": "no goal response"}
        handle = handle_future.result()
        if not handle.accepted:
            return {"answered": True, "accepted": False, "planned": False, "message": "rejected"}
        result_future = probe.in_executor(handle.get_result_async)
        if not probe.wait_until(lambda: result_future.done() or not process.alive(), goal_timeout_s):
            return {"answered": False, "message": "no result"}
        result = result_future.result()
        planned = result.status == 4  # STATUS_SUCCEEDED: a plan came back (success or not)
        return {
            "answered": True,
            "accepted": True,
            "planned": planned,
            "success": bool(result.result.success),
            "message": result.result.message,
            "points": len(result.result.trajectory.points),
            "seconds": round(time.monotonic() - started, 2),
        }

    def publish_meshes(array):
        before = probe.diagnostic_number(node, "meshes_received", 0) + probe.diagnostic_number(
            node, "meshes_rejected", 0
        )
        meshes.publish(array)
        probe.wait_until(
            lambda: (
                probe.diagnostic_number(node, "meshes_received", 0)
                + probe.diagnostic_number(node, "meshes_rejected", 0)
                > before
            ),
            10.0,
        )

    results = []

    def record(name, expect, answer, refusal_expected):
        ok = answer.get("answered", False) and (not refusal_expected or not answer.get("planned", True))
        results.append(
            {
                "name": name,
                "expect": expect,
                "ok": bool(ok),
                "outcome": "planned" if answer.get("planned") else "refused",
                "message": answer.get("message", "")[:200],
                "seconds": answer.get("seconds"),
            }
        )

    probe.wait_for_subscribers([meshes, joints], 30.0)
    publish_meshes(_mesh_case(None)())
    # the first goal waits until the node holds meshes and fresh joint states (a loaded machine can
    # take seconds to match the subscriptions); every later case is sent at once
    probe.wait_until(
        lambda: (
            probe.diagnostic(node).get("joint_states") == "ok"
            and probe.diagnostic_number(node, "meshes_received", 0) >= 1
        ),
        30.0,
    )
    record("valid goal (before)", "valid", goal(target_id=1), False)
    results[-1]["ok"] = results[-1]["ok"] and results[-1]["outcome"] == "planned"
    for name, mutate, expect in MESH_CASES:
        publish_meshes(_mesh_case(mutate)())
        target = 1 if name == "table height NaN" else 2
        answer = goal(target_id=target)
        record(f"meshes: {name}", expect, answer, refusal_expected=expect == "reject" and target == 2)
    publish_meshes(_mesh_case(None)())
    for name, kwargs in [
        ("unknown target id 999", {"target_id": 999}),
        ("meshes_stamp of no array held", {"meshes_stamp_s": 12345}),
        ("unknown task 9", {"task": 9}),
        ("NaN goal displacement", {"task": Manipulate.Goal.TASK_PUSH, "displacement": (float("nan"), 0.0, 0.0)}),
        ("negative tolerance", {"task": Manipulate.Goal.TASK_PUSH, "displacement": (0.05, 0, 0), "tolerance_m": -1.0}),
    ]:
        record(f"goal: {name}", "reject", goal(**kwargs), refusal_expected=True)
    for name, msg in [
        ("NaN joint positions", joint_state_msg(q=np.full(7, np.nan))),
        ("joint names missing", JointState(name=["a"], position=[0.0])),
        ("names/positions length mismatch", JointState(name=list(robot.JOINT_NAMES), position=[0.0])),
    ]:
        joint_msg["msg"] = msg
        time.sleep(0.5)
        record(f"joint_states: {name}", "reject", goal(target_id=1), refusal_expected=True)
    joint_msg["msg"] = joint_state_msg()
    time.sleep(0.5)
    if crowded_objects:
        publish_meshes(_mesh_case(None, n_extra=crowded_objects - 2)())
        record(f"{crowded_objects} objects", "valid", goal(target_id=1), False)
    publish_meshes(_mesh_case(None)())
    record("valid goal (after)", "valid", goal(target_id=1), False)
    results[-1]["ok"] = results[-1]["ok"] and results[-1]["outcome"] == "planned"
    with probe.lock:
        invalid = [p for t in trajectories for p in trajectory_problems(t)]
        published = len(trajectories)
    planned = sum(r["outcome"] == "planned" for r in results)
    return finish_report(
        node,
        process,
        results,
        invalid,
        {
            "action_server_ready": ready,
            "trajectories_published": published,
            "goals_planned": planned,
        },
    )
