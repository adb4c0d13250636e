"""A plan as a ros2_control robot executes it: the arm's trajectory for its joint trajectory
controller, and the gripper's set points for its gripper controller, each with the time it is due.

The planner commands the finger as one more joint, open or closed for stretches of the plan; a
gripper controller takes one set point per goal. Each change of the finger's command becomes a
gripper goal, due when the finger would start moving towards it (the time of the point before). Pure:
no rclpy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Finger set points closer than this (m) are one set point.
SAME_GRIPPER_POSITION_M = 1e-5


@dataclass(frozen=True)
class GripperSetPoint:
    due_s: float  # from the trajectory's start, s
    position_m: float


@dataclass(frozen=True)
class RobotCommands:
    arm_joint_names: tuple[str, ...]
    times_s: np.ndarray  # [n] from the trajectory's start, s
    arm_positions: np.ndarray  # [n, arm joints], rad
    gripper: tuple[GripperSetPoint, ...]


def split_plan(joint_names, times_s, positions, finger_joint: str, gripper_now_m: float | None) -> RobotCommands:
    """The planned trajectory (joint_names with the finger among them, times s, positions [n, joints])
    as arm and gripper commands. gripper_now_m: the gripper's last set point (None: none sent yet), so
    a plan that starts where the gripper already is sends no gripper goal at its start."""
    names = list(joint_names)
    if finger_joint not in names:
        raise ValueError(f"the plan has no {finger_joint} column: {names}")
    times_s = np.asarray(times_s, dtype=np.float64)
    positions = np.asarray(positions, dtype=np.float64).reshape(len(times_s), len(names))
    finger = names.index(finger_joint)
    arm = [i for i in range(len(names)) if i != finger]
    fingers = positions[:, finger]
    gripper = []
    if len(fingers) and (gripper_now_m is None or abs(fingers[0] - gripper_now_m) > SAME_GRIPPER_POSITION_M):
        gripper.append(GripperSetPoint(0.0, float(fingers[0])))
    for i in np.flatnonzero(np.abs(np.diff(fingers)) > SAME_GRIPPER_POSITION_M) + 1:
        gripper.append(GripperSetPoint(float(times_s[i - 1]), float(fingers[i])))
    return RobotCommands(tuple(names[i] for i in arm), times_s, positions[:, arm], tuple(gripper))
