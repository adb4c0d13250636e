"""The graph on simulated time: sim_node publishes /clock, segmentation_node runs with
use_sim_time:=true, and everything it stamps (segmented frames, diagnostics) follows /clock, not the
wall clock. sim_node itself accepts use_sim_time:=true (it is the clock source and keeps ticking)."""

import time

from diagnostic_msgs.msg import DiagnosticArray
from rosgraph_msgs.msg import Clock

from arm_benchmarks.robustness.messages import stamp_of
from arm_benchmarks.robustness.probe import Probe
from arm_interfaces.msg import SegmentedFrame

from ros_helpers import start_node

SIM = {"n_objects": 3, "width": 320, "height": 240, "camera_rate_hz": 2.0, "use_sim_time": True}


def seconds(time_msg) -> float:
    return time_msg.sec + 1e-9 * time_msg.nanosec


def test_segmentation_on_sim_time_stamps_its_outputs_with_the_sim_clock(tmp_path):
    probe = Probe("sim_time_probe")
    nodes = []
    try:
        clock = probe.record(Clock, "/clock", 10, keep=5000)
        frames = probe.record(SegmentedFrame, "arm/segmented_frame", 10)
        diagnostics = probe.record(DiagnosticArray, "/diagnostics", 50)
        nodes.append(start_node("sim", tmp_path, params=SIM))
        nodes.append(
            start_node("segmentation", tmp_path, params={"use_sim_time": True, "image_reliability": "reliable"})
        )

        def segmentation_diagnostics():
            with probe.lock:
                return [d for d in diagnostics if any(s.name.startswith("segmentation_node") for s in d.status)]

        done = probe.wait_until(
            lambda: len(frames) >= 2 and len(segmentation_diagnostics()) >= 2 and len(clock) > 0, 120.0, poll_s=0.2
        )
        alive = {n.key: n.alive() for n in nodes}
        with probe.lock:
            clock_s = [seconds(c.clock) for c in clock]
            frame_s = [stamp_of(f) for f in frames]
        diag_s = [seconds(d.header.stamp) for d in segmentation_diagnostics()]
    finally:
        probe.close()
        codes = {n.key: n.stop() for n in nodes}
    logs = {n.key: n.log()[-1500:] for n in nodes}
    assert done, (len(frames), len(diag_s), logs)
    assert all(alive.values()) and all(code == 0 for code in codes.values()), (alive, codes, logs)
    wall_s = time.time()
    assert clock_s and max(clock_s) < 1e6 < wall_s, clock_s[-3:]  # simulated seconds since the sim started
    # frames carry the camera stamps of the sim; the node's own clock (diagnostics) follows /clock too
    # (the probe may match /clock a little after the sim started: the lower bound is the sim's start)
    assert all(0.0 < s <= max(clock_s) for s in frame_s), (frame_s, clock_s[0], clock_s[-1])
    assert all(0.0 < s <= max(clock_s) + 1e-6 for s in diag_s), (diag_s, clock_s[-1])
    assert diag_s == sorted(diag_s), diag_s
