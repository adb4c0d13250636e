"""Malformed and extreme inputs for every node, sent over DDS by a Probe, and what each node must do:
stay alive, log a clear error (rate-limited), publish nothing wrong. Each runner returns a report
(plain dict) that tests assert on and bench_robustness writes to results/robustness/summary.json.

Expectations per case: "reject" = nothing may be published for it and an error naming the reason
is expected; "valid" = the node may publish (what it publishes must pass the validator) or reject
it with an error; "silent" = an incomplete input that must produce nothing (no error required).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable

import numpy as np
import trimesh
from builtin_interfaces.msg import Duration
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from arm_benchmarks.robustness import (
    error_lines,
    joint_state_msg,
    joint_state_problems,
    mesh_array_problems,
    rate_limit_violations,
    segmented_frame_msg,
    segmented_frame_problems,
    stamp_of,
    tracebacks,
    trajectory_problems,
)
from arm_ros.conversions.images import numpy_to_image
from arm_ros.conversions.meshes import mesh_to_msg
from arm_ros.conversions.poses import matrix_to_pose
from arm_sim import robot


@dataclasses.dataclass
class Case:
    name: str
    expect: str  # "reject" | "valid" | "silent"
    build: Callable  # stamp_s -> {topic: message}
    reason: str = ""  # text the node's error log should contain for it


def _finish_report(node: str, process, results: list[dict], invalid_outputs: list[str], extra: dict) -> dict:
    log = process.log()
    lines = error_lines(log)
    causes: dict[str, int] = {}
    for line in lines:
        causes[line.cause] = causes.get(line.cause, 0) + 1
    missing = [r["name"] for r in results if r.get("reason") and r["reason"].lower() not in log.lower()]
    return {
        "node": node,
        "inputs_tried": len(results),
        "cases": results,
        "cases_failed": [r["name"] for r in results if not r["ok"]],
        "alive": process.alive(),
        "error_lines": len(lines),
        "error_lines_by_cause": causes,
        "rate_limit_violations": rate_limit_violations(lines),
        "reasons_not_logged": missing,
        "tracebacks": tracebacks(log),
        "invalid_outputs": invalid_outputs,
        **extra,
    }


def _judge(expect: str, published: bool, rejected: bool) -> tuple[bool, str]:
    outcome = "published" if published else ("rejected" if rejected else "nothing")
    if expect == "reject":
        return not published, outcome
    if expect == "silent":
        return not published, outcome
    return True, outcome


# --- segmentation_node ----------------------------------------------------------------------------
def _camera_case(frame, mutate=None, drop: tuple = ()):
    from arm_benchmarks.robustness import camera_messages

    def build(stamp_s):
        msgs = camera_messages(frame, stamp_s)
        if mutate is not None:
            mutate(msgs)
        for topic in drop:
            msgs.pop(topic)
        return msgs

    return build


def _set_depth(value_fn):
    def mutate(msgs):
        old = msgs["camera/depth/image_raw"]
        depth = np.frombuffer(bytes(old.data), np.float32).reshape(old.height, old.width).copy()
        msgs["camera/depth/image_raw"] = numpy_to_image(value_fn(depth), "32FC1", old.header)

    return mutate


def _sprinkle(depth):
    rng = np.random.default_rng(0)
    mask = rng.random(depth.shape)
    depth[mask < 0.1] = np.nan
    depth[(mask >= 0.1) & (mask < 0.15)] = np.inf
    depth[(mask >= 0.15) & (mask < 0.2)] = -1.0
    return depth


def _field(topic, **values):
    def mutate(msgs):
        for name, value in values.items():
            setattr(msgs[topic], name, value)

    return mutate


def _rgb_smaller(msgs):
    old = msgs["camera/color/image_raw"]
    rgb = np.frombuffer(bytes(old.data), np.uint8).reshape(old.height, old.width, 3)
    msgs["camera/color/image_raw"] = numpy_to_image(rgb[: old.height // 2, : old.width // 2], "rgb8", old.header)


def _depth_mm(msgs):
    old = msgs["camera/depth/image_raw"]
    depth = np.frombuffer(bytes(old.data), np.float32).reshape(old.height, old.width)
    msgs["camera/depth/image_raw"] = numpy_to_image(np.round(depth * 1000.0).astype(np.uint16), "16UC1", old.header)


def _truncate(topic):
    def mutate(msgs):
        msgs[topic].data = bytes(msgs[topic].data)[: len(msgs[topic].data) // 3]

    return mutate


def _info_k(values):
    def mutate(msgs):
        msgs["camera/camera_info"].k = [float(v) for v in values]

    return mutate


def _pose(position=None, orientation=None):
    def mutate(msgs):
        pose = msgs["camera/pose"].pose
        if position is not None:
            pose.position.x, pose.position.y, pose.position.z = position
        if orientation is not None:
            pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = orientation

    return mutate


def _huge_empty_image(msgs):
    msgs["camera/depth/image_raw"].height = 100000
    msgs["camera/depth/image_raw"].width = 100000
    msgs["camera/depth/image_raw"].step = 400000


def segmentation_cases(frames: dict) -> list[Case]:
    """frames: {"normal", "empty", "crowded"} RgbdFrames of one camera."""
    normal = frames["normal"]
    nan, inf = float("nan"), float("inf")
    return [
        Case("depth all NaN", "valid", _camera_case(normal, _set_depth(lambda d: np.full_like(d, nan)))),
        Case("depth all +inf", "valid", _camera_case(normal, _set_depth(lambda d: np.full_like(d, inf)))),
        Case("depth all zero", "valid", _camera_case(normal, _set_depth(np.zeros_like))),
        Case("depth all negative", "valid", _camera_case(normal, _set_depth(lambda d: -d))),
        Case("depth with NaN/inf/negative pixels", "valid", _camera_case(normal, _set_depth(_sprinkle))),
        Case("depth 16UC1 millimetres", "valid", _camera_case(normal, _depth_mm)),
        Case("rgb smaller than depth", "reject", _camera_case(normal, _rgb_smaller), "rgb is"),
        Case(
            "rgb encoding yuv422",
            "reject",
            _camera_case(normal, _field("camera/color/image_raw", encoding="yuv422")),
            "yuv422",
        ),
        Case(
            "depth encoding 64FC1",
            "reject",
            _camera_case(normal, _field("camera/depth/image_raw", encoding="64FC1")),
            "64FC1",
        ),
        Case("depth data truncated", "reject", _camera_case(normal, _truncate("camera/depth/image_raw")), "too short"),
        Case("depth 100000x100000 without data", "reject", _camera_case(normal, _huge_empty_image), "too short"),
        Case("zero intrinsics", "reject", _camera_case(normal, _info_k([0.0] * 9)), "intrinsics"),
        Case("NaN intrinsics", "reject", _camera_case(normal, _info_k([nan] * 9)), "intrinsics"),
        Case("camera_info missing", "silent", _camera_case(normal, drop=("camera/camera_info",))),
        Case("pose NaN position", "reject", _camera_case(normal, _pose(position=(nan, 0.0, 0.5))), "non-finite"),
        Case("pose inf position", "reject", _camera_case(normal, _pose(position=(inf, 0.0, 0.5))), "non-finite"),
        Case(
            "pose zero quaternion",
            "reject",
            _camera_case(normal, _pose(orientation=(0.0, 0.0, 0.0, 0.0))),
            "quaternion",
        ),
        Case("empty scene", "valid", _camera_case(frames["empty"])),
        Case(f"{int(frames['crowded'].labels.max())} objects", "valid", _camera_case(frames["crowded"])),
    ]


def run_segmentation_bad_inputs(
    probe,
    process,
    frames: dict,
    output_topic: str = "arm/segmented_frame",
    input_prefix: str = "",
    reliability: str = "reliable",
    case_timeout_s: float = 20.0,
) -> dict:
    """Send every segmentation case (each with its own stamp), then a valid frame; judge each."""
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import CameraInfo, Image

    from arm_interfaces.msg import SegmentedFrame
    from arm_ros.common import sensor_qos

    types = {
        "camera/color/image_raw": Image,
        "camera/depth/image_raw": Image,
        "camera/camera_info": CameraInfo,
        "camera/pose": PoseStamped,
    }
    qos = sensor_qos(reliability, depth=5)
    publishers = {t: probe.publisher(k, input_prefix + t, qos) for t, k in types.items()}
    outputs = probe.record(SegmentedFrame, output_topic, 10)
    probe.watch_diagnostics()
    node = "segmentation_node"

    def rejected():
        return probe.diagnostic_number(node, "frames_rejected", 0.0)

    def published(stamp_s):
        with probe.lock:
            return any(abs(stamp_of(m) - stamp_s) < 1e-6 for m in outputs)

    def send(msgs):
        for topic in types:
            if topic in msgs:
                publishers[topic].publish(msgs[topic])

    ready = probe.wait_for_subscribers(publishers.values(), 30.0)
    cases = [Case("valid frame (before)", "valid", _camera_case(frames["normal"]))]
    cases += segmentation_cases(frames)
    cases += [Case("valid frame (after)", "valid", _camera_case(frames["normal"]))]
    results = []
    for i, case in enumerate(cases):
        stamp_s = 10.0 + i
        before = rejected()
        send(case.build(stamp_s))
        timeout = 2.0 if case.expect == "silent" else case_timeout_s
        probe.wait_until(lambda s=stamp_s, b=before: published(s) or rejected() > b, timeout)
        if case.expect != "silent":  # diagnostics come once a second: let a late rejection count arrive
            probe.wait_until(lambda s=stamp_s, b=before: published(s) or rejected() > b, 1.5)
        was_published, was_rejected = published(stamp_s), rejected() > before
        ok, outcome = _judge(case.expect, was_published, was_rejected)
        if case.name.startswith("valid frame"):
            ok = was_published
        results.append(
            {
                "name": case.name,
                "expect": case.expect,
                "outcome": outcome,
                "ok": ok,
                "reason": case.reason if outcome == "rejected" else "",
            }
        )
    with probe.lock:
        invalid = [f"t={stamp_of(m):.0f}: {p}" for m in outputs for p in segmented_frame_problems(m)]
    return _finish_report(node, process, results, invalid, {"subscribers_matched": ready})


# --- reconstruction_node --------------------------------------------------------------------------
def _frame_case(frame, mutate=None, labels=None):
    def build(stamp_s):
        msg = segmented_frame_msg(frame, stamp_s, labels)
        if mutate is not None:
            mutate(msg)
        return {"arm/segmented_frame": msg}

    return build


def _frame_depth(value_fn):
    def mutate(msg):
        old = msg.depth
        depth = np.frombuffer(bytes(old.data), np.float32).reshape(old.height, old.width).copy()
        msg.depth = numpy_to_image(value_fn(depth), "32FC1", old.header)

    return mutate


def _frame_image_half(field, encoding):
    def mutate(msg):
        old = getattr(msg, field)
        dtype = np.uint8 if encoding == "rgb8" else np.uint16
        channels = 3 if encoding == "rgb8" else 1
        array = np.frombuffer(bytes(old.data), dtype).reshape(old.height, old.width, channels)
        setattr(msg, field, numpy_to_image(array[: old.height // 2, : old.width // 2], encoding, old.header))

    return mutate


def _frame_set(path, value):
    def mutate(msg):
        target = msg
        *parents, last = path.split(".")
        for name in parents:
            target = getattr(target, name)
        setattr(target, last, value)

    return mutate


def _frame_pose(position=None, orientation=None):
    def mutate(msg):
        if position is not None:
            msg.camera_pose.position.x, msg.camera_pose.position.y, msg.camera_pose.position.z = position
        if orientation is not None:
            o = msg.camera_pose.orientation
            o.x, o.y, o.z, o.w = orientation

    return mutate


def reconstruction_cases(frames: dict, crowded: bool = True) -> list[Case]:
    normal = frames["normal"]
    nan = float("nan")
    cases = [
        Case("depth all NaN", "valid", _frame_case(normal, _frame_depth(lambda d: np.full_like(d, nan)))),
        Case("depth with NaN/inf/negative pixels", "valid", _frame_case(normal, _frame_depth(_sprinkle))),
        Case("rgb smaller than depth", "reject", _frame_case(normal, _frame_image_half("rgb", "rgb8")), "rgb"),
        Case(
            "labels smaller than depth", "reject", _frame_case(normal, _frame_image_half("labels", "16UC1")), "labels"
        ),
        Case("labels encoding rgb8", "reject", _frame_case(normal, _frame_set("labels.encoding", "rgb8")), "rgb8"),
        Case("depth encoding mono8", "reject", _frame_case(normal, _frame_set("depth.encoding", "mono8")), "mono8"),
        Case(
            "unsupported encoding yuv422",
            "reject",
            _frame_case(normal, _frame_set("depth.encoding", "yuv422")),
            "yuv422",
        ),
        Case(
            "labels data truncated", "reject", _frame_case(normal, _frame_set("labels.data", b"\x00" * 10)), "too short"
        ),
        Case("zero intrinsics", "reject", _frame_case(normal, _frame_set("camera_info.k", [0.0] * 9)), "intrinsics"),
        Case("NaN intrinsics", "reject", _frame_case(normal, _frame_set("camera_info.k", [nan] * 9)), "intrinsics"),
        Case("pose NaN position", "reject", _frame_case(normal, _frame_pose(position=(nan, 0.0, 0.5))), "non-finite"),
        Case(
            "pose zero quaternion",
            "reject",
            _frame_case(normal, _frame_pose(orientation=(0.0, 0.0, 0.0, 0.0))),
            "quaternion",
        ),
        Case("no rgb", "valid", _frame_case(normal, _frame_set("rgb", numpy_to_image(np.zeros((0, 0, 3)), "rgb8")))),
        Case("empty scene", "valid", _frame_case(frames["empty"])),
        Case("instance ids not in the labels", "valid", _frame_case(normal, _frame_set("instance_ids", [1, 2, 999]))),
    ]
    if crowded:
        cases.append(Case(f"{int(frames['crowded'].labels.max())} objects", "valid", _frame_case(frames["crowded"])))
    return cases


def _frame_rejections(log: str) -> int:
    return sum(1 for line in error_lines(log) if not line.text.startswith("object "))


def _wait_log_quiet(process, quiet_s: float = 0.5, timeout_s: float = 5.0) -> None:
    """Wait until the node's log stopped growing (the lines of the previous frame are written)."""
    deadline = time.monotonic() + timeout_s
    size, since = -1, time.monotonic()
    while time.monotonic() < deadline:
        current = process.log_path.stat().st_size
        if current != size:
            size, since = current, time.monotonic()
        elif time.monotonic() - since >= quiet_s:
            return
        time.sleep(0.1)


def run_reconstruction_bad_inputs(
    probe, process, frames: dict, crowded: bool = True, valid_timeout_s: float = 180.0, reject_wait_s: float = 1.0
) -> dict:
    """Send each reconstruction case; valid ones are waited for (one at a time: latest-frame
    processing would drop a frame sent while another is being reconstructed)."""
    from arm_interfaces.msg import ReconstructedObjectArray, SegmentedFrame
    from arm_ros.common import latched_qos

    publisher = probe.publisher(SegmentedFrame, "arm/segmented_frame", 10)
    outputs = probe.record(ReconstructedObjectArray, "arm/meshes", latched_qos(depth=1))
    probe.watch_diagnostics()
    node = "reconstruction_node"

    def published(stamp_s):
        with probe.lock:
            return any(abs(stamp_of(m) - stamp_s) < 1e-6 for m in outputs)

    ready = probe.wait_for_subscribers([publisher], 60.0)
    cases = reconstruction_cases(frames, crowded)
    cases.append(Case("valid frame (after)", "valid", _frame_case(frames["normal"])))
    results = []
    for i, case in enumerate(cases):
        stamp_s = 10.0 + i
        _wait_log_quiet(process)
        started = time.monotonic()
        rejections_before = _frame_rejections(process.log())
        publisher.publish(case.build(stamp_s)["arm/segmented_frame"])
        if case.expect == "valid":  # a valid case may be rejected (logged, unless the rate limiter holds it)
            probe.wait_until(
                lambda s=stamp_s, n=rejections_before: (
                    published(s) or _frame_rejections(process.log()) > n or not process.alive()
                ),
                valid_timeout_s,
                poll_s=0.2,
            )
        else:
            probe.wait_until(lambda s=stamp_s: published(s), reject_wait_s)
        was_published = published(stamp_s)
        ok, outcome = _judge(case.expect, was_published, False)
        if case.name.startswith("valid frame"):
            ok = was_published
        results.append(
            {
                "name": case.name,
                "expect": case.expect,
                "outcome": outcome,
                "ok": ok,
                "seconds": round(time.monotonic() - started, 2),
                "reason": case.reason if case.expect == "reject" else "",
            }
        )

    def accounted():  # diagnostics follow the meshes of the same frame: wait for the last of them
        keys = ("frames_processed", "frames_rejected", "frames_dropped")
        return sum(probe.diagnostic_number(node, k, 0) for k in keys) >= len(cases)

    probe.wait_until(accounted, 10.0)
    counters = {
        k: probe.diagnostic_number(node, k, -1)
        for k in ("frames_received", "frames_processed", "frames_rejected", "frames_dropped")
    }
    with probe.lock:
        invalid = [f"t={stamp_of(m):.0f}: {p}" for m in outputs for p in mesh_array_problems(m)]
    return _finish_report(
        node,
        process,
        results,
        invalid,
        {
            "subscribers_matched": ready,
            "frames_sent": len(cases),
            "counters": counters,
            "rejects_expected": sum(c.expect == "reject" for c in cases),
        },
    )


# --- plan_node ------------------------------------------------------------------------------------
def _box_object(object_id, centre, extents=(0.05, 0.05, 0.08)):
    from arm_interfaces.msg import ReconstructedObject

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
    from arm_interfaces.msg import ReconstructedObjectArray

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
    from rclpy.action import ActionClient
    from sensor_msgs.msg import JointState

    from arm_interfaces.action import Manipulate
    from arm_interfaces.msg import ReconstructedObjectArray
    from arm_ros.common import latched_qos

    node = "plan_node"
    meshes = probe.publisher(ReconstructedObjectArray, "arm/meshes", latched_qos())
    joints = probe.publisher(JointState, "joint_states", 10)
    trajectories = probe.record(JointTrajectory, "arm/joint_trajectory", 10)
    probe.watch_diagnostics()
    joint_msg = {"msg": joint_state_msg()}
    probe.node.create_timer(0.1, lambda: joints.publish(joint_msg["msg"]))
    action = ActionClient(probe.node, Manipulate, "arm/manipulate")
    ready = action.wait_for_server(timeout_sec=60.0)

    def goal(task=Manipulate.Goal.TASK_GRASP, target_id=1, displacement=(0.0, 0.0, 0.0), tolerance_m=0.0):
        started = time.monotonic()
        g = Manipulate.Goal(task=task, target_id=target_id, tolerance_m=tolerance_m)
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
    return _finish_report(
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


# --- sim_node ------------------------------------------------------------------------------------
def _trajectory(names, points):
    msg = JointTrajectory(joint_names=list(names))
    for t, q in points:
        sec = math.floor(t) if math.isfinite(t) else 0
        point = JointTrajectoryPoint(positions=[float(v) for v in q])
        point.time_from_start = Duration(sec=int(sec), nanosec=int((t - sec) * 1e9) if math.isfinite(t) else 0)
        msg.points.append(point)
    return msg


def sim_trajectory_cases() -> list[tuple[str, str, JointTrajectory]]:
    names = list(robot.JOINT_NAMES)
    home = list(robot.HOME_Q)
    return [
        ("NaN positions", "reject", _trajectory(names, [(1.0, [float("nan")] * 7)])),
        ("unknown joint names", "reject", _trajectory(["elbow", "knee"], [(1.0, [0.0, 0.0])])),
        ("no points", "reject", _trajectory(names, [])),
        ("positions shorter than joint names", "reject", _trajectory(names, [(1.0, [0.0, 0.0])])),
        ("time_from_start decreasing", "reject", _trajectory(names, [(2.0, home), (1.0, home)])),
        ("one hour long", "reject", _trajectory(names, [(3600.0, home)])),
        ("positions far outside the limits", "valid", _trajectory(names, [(0.5, [100.0] * 7)])),
    ]


def run_sim_bad_inputs(probe, process, settle_s: float = 2.0) -> dict:
    from sensor_msgs.msg import JointState

    node = "sim_node"
    states = probe.record(JointState, "joint_states", 10, keep=500)
    publisher = probe.publisher(JointTrajectory, "arm/joint_trajectory", 10)
    ready = probe.wait_for_subscribers([publisher], 90.0) and probe.wait_until(lambda: len(states) > 0, 90.0)
    results = []
    for name, expect, msg in sim_trajectory_cases():
        executing_before = process.log().count("executing trajectory")
        publisher.publish(msg)
        accepted = probe.wait_until(
            lambda n=executing_before: process.log().count("executing trajectory") > n, settle_s
        )
        ok = process.alive() and (expect != "reject" or not accepted)
        results.append(
            {
                "name": name,
                "expect": expect,
                "outcome": "accepted" if accepted else "rejected",
                "ok": ok,
                "reason": "rejected trajectory" if expect == "reject" else "",
            }
        )
    probe.wait_until(lambda: False, settle_s)  # let an accepted extreme trajectory run
    with probe.lock:
        invalid = [p for s in states for p in joint_state_problems(s)]
        received = len(states)
    return _finish_report(
        node, process, results, invalid, {"subscribers_matched": ready, "joint_states_checked": received}
    )


# --- parameters at start-up ------------------------------------------------------------------------
PARAMETER_CASES = [
    ("segmentation", "sync_queue_size", 0, "range"),
    ("segmentation", "image_reliability", "sometimes", "choice"),
    ("reconstruction", "k", 100.0, "range"),
    ("reconstruction", "method", "magic", "choice"),
    ("planner", "num_paths", 1, "range"),
    ("planner", "steps", "many", "type"),
    ("sim", "n_objects", 99, "range"),
    ("sim", "split", "test", "choice"),
]


def run_parameter_validation(log_dir, timeout_s: float = 60.0) -> list[dict]:
    """Start every node with one invalid parameter (all at once); each must exit with code 2, name the
    parameter and print no traceback."""
    from arm_benchmarks.robustness import NodeProcess, node_built

    started = []
    for i, (key, name, value, _) in enumerate(PARAMETER_CASES):
        if node_built(key):
            process = NodeProcess(key, log_dir / f"params_{i}" / f"{key}.log", params={name: value})
            started.append((i, process))
    results = []
    for i, process in started:
        key, name, value, kind = PARAMETER_CASES[i]
        code = process.wait(timeout_s)
        if code is None:
            process.stop()
        log = process.log()
        results.append(
            {
                "node": key,
                "parameter": name,
                "value": value,
                "kind": kind,
                "exit_code": code,
                "names_parameter": name in log,
                "tracebacks": tracebacks(log),
                "ok": code == 2 and name in log and not tracebacks(log),
            }
        )
    return results
