"""sim_node: malformed and extreme inputs and what the node must do with them."""

from __future__ import annotations

import math

from builtin_interfaces.msg import Duration
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from arm_benchmarks.robustness.cases.common import finish_report
from arm_benchmarks.robustness.validators import (
    joint_state_problems,
)
from arm_sim import robot


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
        ("stamped a day off the sim clock (started on arrival)", "valid", _stamped(_trajectory(names, [(0.5, home)]))),
    ]


def _stamped(msg: JointTrajectory, sec: int = 86_400) -> JointTrajectory:
    msg.header.stamp.sec = sec
    return msg


def run_sim_bad_inputs(probe, process, settle_s: float = 2.0) -> dict:
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
    return finish_report(
        node, process, results, invalid, {"subscribers_matched": ready, "joint_states_checked": received}
    )
