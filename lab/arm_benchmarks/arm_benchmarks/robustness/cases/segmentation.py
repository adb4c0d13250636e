"""segmentation_node: malformed and extreme inputs and what the node must do with them."""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import CameraInfo, Image

from arm_benchmarks.robustness.cases.common import Case, case_result, finish_report, sprinkle_invalid_depth
from arm_benchmarks.robustness.messages import camera_messages, stamp_of
from arm_benchmarks.robustness.validators import (
    segmented_frame_problems,
)
from arm_interfaces.msg import SegmentedFrame
from arm_ros.common import sensor_qos
from arm_ros.conversions.images import numpy_to_image


def _camera_case(frame, mutate=None, drop: tuple = ()):
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
        Case("depth with NaN/inf/negative pixels", "valid", _camera_case(normal, _set_depth(sprinkle_invalid_depth))),
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
        reason = case.reason if was_rejected and not was_published else ""  # outcome "rejected"
        results.append(case_result(case, was_published, was_rejected, reason))
    with probe.lock:
        invalid = [f"t={stamp_of(m):.0f}: {p}" for m in outputs for p in segmented_frame_problems(m)]
    return finish_report(node, process, results, invalid, {"subscribers_matched": ready})
