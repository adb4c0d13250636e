"""reconstruction_node: malformed and extreme inputs and what the node must do with them."""

from __future__ import annotations

import time

import numpy as np

from arm_benchmarks.robustness.cases.common import Case, case_result, finish_report, sprinkle_invalid_depth
from arm_benchmarks.robustness.logs import error_lines
from arm_benchmarks.robustness.messages import segmented_frame_msg, stamp_of
from arm_benchmarks.robustness.validators import (
    mesh_array_problems,
)
from arm_interfaces.msg import ReconstructedObjectArray, SegmentedFrame
from arm_ros.common import latched_qos
from arm_ros.conversions.images import numpy_to_image


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
        Case("depth with NaN/inf/negative pixels", "valid", _frame_case(normal, _frame_depth(sprinkle_invalid_depth))),
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
        reason = case.reason if case.expect == "reject" else ""
        seconds = round(time.monotonic() - started, 2)
        results.append(case_result(case, was_published, False, reason, seconds=seconds))

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
    return finish_report(
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
