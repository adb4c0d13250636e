"""sim_node's ros2_control stand-ins: the arm's joint trajectory controller and the gripper's action
controller, served on the simulated robot with ros2_control's action interfaces.

- `<arm_controller>/follow_joint_trajectory` (control_msgs/action/FollowJointTrajectory), as
  joint_trajectory_controller serves it: a goal names every arm joint (else it is rejected); its
  trajectory starts at its header stamp (zero: on arrival) and replaces the one running, whose goal is
  canceled; feedback carries the desired, actual and error positions; at the trajectory's end the goal
  succeeds when each joint is within its goal tolerance (0: not checked), else it aborts with
  GOAL_TOLERANCE_VIOLATED once goal_time_tolerance has passed too. A cancel holds the arm where it is.
- `<gripper_controller>/gripper_cmd` (control_msgs/action/GripperCommand), as gripper_action_controller
  serves a position-commanded gripper: the finger goes to command.position (m; max_effort is not
  applied); the goal succeeds with reached_goal once within `GRIPPER_GOAL_TOLERANCE_M`, or with
  stalled (on an object) once the finger moved less than `STALL_MOTION_M` in `STALL_TIMEOUT_S`.

Goals finish on the sim's clock: `tick()` runs after every physics tick.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from control_msgs.action import FollowJointTrajectory, GripperCommand
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.task import Future
from trajectory_msgs.msg import JointTrajectoryPoint

from arm_ros.conversions.stamps import time_ns
from arm_sim import robot

# A trajectory stamped further than this from the sim clock (s) starts on arrival instead.
STAMP_TOLERANCE_S = 5.0
GRIPPER_GOAL_TOLERANCE_M = 0.002
STALL_MOTION_M = 2e-4
STALL_TIMEOUT_S = 0.5
FEEDBACK_PERIOD_S = 0.1


def _seconds(duration) -> float:
    return duration.sec + 1e-9 * duration.nanosec


def trajectory_start_s(stamp, now_s: float) -> tuple[float | None, str]:
    """A trajectory's time zero on the sim clock (s) from its header stamp, and a warning: None (start
    now) for a zero stamp, or for one more than STAMP_TOLERANCE_S off the sim clock (a sender not on
    /clock), with the warning then."""
    start_s = 1e-9 * time_ns(stamp)
    if start_s == 0.0:
        return None, ""
    if abs(start_s - now_s) > STAMP_TOLERANCE_S:
        return None, (
            f"trajectory stamped {start_s:.3f} s, {start_s - now_s:+.3f} s from the sim clock "
            "(is the sender on /clock, use_sim_time:=true?); started now"
        )
    return start_s, ""


@dataclass
class _ArmGoal:
    handle: object
    joint_names: list[str]
    final: np.ndarray  # the trajectory's last positions, rad, in joint_names order
    end_s: float  # sim time the trajectory ends, s
    time_tolerance_s: float
    position_tolerance: np.ndarray  # rad per joint (0: not checked)
    done: Future = field(default_factory=Future)
    next_feedback_s: float = 0.0


@dataclass
class _GripperGoal:
    handle: object
    target_m: float
    history: list[tuple[float, float]] = field(default_factory=list)  # (sim time s, finger position m)
    done: Future = field(default_factory=Future)
    next_feedback_s: float = 0.0


class SimControllers:
    """The arm and gripper action servers of `node` on `session` (arm_sim.core.SimSession)."""

    def __init__(self, node, session, arm_controller: str, gripper_controller: str, sim_time_s, header):
        self.node, self.session = node, session
        self.sim_time_s, self.header = sim_time_s, header  # callables: the sim clock (s), a stamped Header
        self.arm_joints = list(robot.JOINT_NAMES)
        self.arm: _ArmGoal | None = None
        self.gripper: _GripperGoal | None = None
        self.goals = {"arm": 0, "gripper": 0}
        self.servers = [
            ActionServer(
                node,
                FollowJointTrajectory,
                f"{arm_controller}/follow_joint_trajectory",
                execute_callback=self._execute_arm,
                goal_callback=self._check_arm_goal,
                cancel_callback=lambda _: CancelResponse.ACCEPT,
            ),
            ActionServer(
                node,
                GripperCommand,
                f"{gripper_controller}/gripper_cmd",
                execute_callback=self._execute_gripper,
                goal_callback=self._check_gripper_goal,
                cancel_callback=lambda _: CancelResponse.ACCEPT,
            ),
        ]

    # --- arm ---------------------------------------------------------------------------------
    def _check_arm_goal(self, goal) -> GoalResponse:
        names = list(goal.trajectory.joint_names)
        if sorted(names) != sorted(self.arm_joints) or not goal.trajectory.points:
            self.node.get_logger().warn(
                f"rejecting a FollowJointTrajectory goal for joints {names} with {len(goal.trajectory.points)} "
                f"points: expected every arm joint {self.arm_joints}"
            )
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    async def _execute_arm(self, handle):
        goal = handle.request
        trajectory = goal.trajectory
        names = list(trajectory.joint_names)
        times = [_seconds(p.time_from_start) for p in trajectory.points]
        positions = [list(p.positions) for p in trajectory.points]
        start_s, warning = trajectory_start_s(trajectory.header.stamp, self.sim_time_s())
        if warning:
            self.node.get_logger().warn(warning, throttle_duration_sec=5.0)
        try:
            self.session.follow(names, times, positions, start_s)
        except ValueError as error:
            handle.abort()
            return FollowJointTrajectory.Result(
                error_code=FollowJointTrajectory.Result.INVALID_GOAL, error_string=str(error)
            )
        self.cancel_arm("replaced by a new trajectory goal")
        self.goals["arm"] += 1
        tolerance = {t.name: t.position for t in goal.goal_tolerance}
        self.arm = _ArmGoal(
            handle,
            names,
            np.asarray(positions[-1], dtype=np.float64),
            (self.sim_time_s() if start_s is None else start_s) + times[-1],
            _seconds(goal.goal_time_tolerance),
            np.array([max(0.0, tolerance.get(n, 0.0)) for n in names]),
        )
        return await self.arm.done

    def cancel_arm(self, why: str) -> None:
        """End the running trajectory goal, which a new trajectory replaced (aborted, error code 0 and
        `why`, as joint_trajectory_controller ends a preempted goal)."""
        if self.arm is not None:
            active, self.arm = self.arm, None
            active.handle.abort()
            active.done.set_result(FollowJointTrajectory.Result(error_string=why))

    def _arm_positions(self, names) -> np.ndarray:
        index = [self.arm_joints.index(n) for n in names]
        return self.session.world.joint_positions()[index]

    def _tick_arm(self, now_s: float) -> None:
        goal = self.arm
        if goal is None:
            return
        actual = self._arm_positions(goal.joint_names)
        if goal.handle.is_cancel_requested:
            self.session.follow(goal.joint_names, [0.05], [actual.tolist()])  # hold where it is
            self.arm = None
            goal.handle.canceled()
            goal.done.set_result(FollowJointTrajectory.Result(error_string="canceled: holding position"))
            return
        error = goal.final - actual
        if now_s >= goal.next_feedback_s:
            goal.next_feedback_s = now_s + FEEDBACK_PERIOD_S
            desired = self.session.command()[[self.arm_joints.index(n) for n in goal.joint_names]]
            goal.handle.publish_feedback(
                FollowJointTrajectory.Feedback(
                    header=self.header(""),
                    joint_names=goal.joint_names,
                    desired=JointTrajectoryPoint(positions=desired.tolist()),
                    actual=JointTrajectoryPoint(positions=actual.tolist()),
                    error=JointTrajectoryPoint(positions=(desired - actual).tolist()),
                )
            )
        if now_s < goal.end_s:
            return
        checked = goal.position_tolerance > 0
        outside = checked & (np.abs(error) > goal.position_tolerance)
        worst = int(np.argmax(np.abs(error)))
        words = f"largest final error {error[worst]:+.4f} rad at {goal.joint_names[worst]}"
        if not outside.any():
            self.arm = None
            goal.handle.succeed()
            goal.done.set_result(FollowJointTrajectory.Result(error_code=0, error_string=words))
        elif now_s >= goal.end_s + goal.time_tolerance_s:
            self.arm = None
            goal.handle.abort()
            joint = goal.joint_names[int(np.argmax(np.where(outside, np.abs(error), -1.0)))]
            goal.done.set_result(
                FollowJointTrajectory.Result(
                    error_code=FollowJointTrajectory.Result.GOAL_TOLERANCE_VIOLATED,
                    error_string=f"{joint} outside its goal tolerance; {words}",
                )
            )

    # --- gripper -----------------------------------------------------------------------------
    def _check_gripper_goal(self, goal) -> GoalResponse:
        if not np.isfinite(goal.command.position):
            self.node.get_logger().warn("rejecting a GripperCommand goal with a non-finite position")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    async def _execute_gripper(self, handle):
        if self.gripper is not None:  # a new goal preempts the running one
            active, self.gripper = self.gripper, None
            active.handle.abort()
            active.done.set_result(self._gripper_result(active, stalled=False, reached=False))
        self.goals["gripper"] += 1
        target = self.session.command_gripper(handle.request.command.position)
        self.gripper = _GripperGoal(handle, target)
        return await self.gripper.done

    def _finger_m(self) -> float:
        return float(self.session.world.joint_positions()[-1])

    def _gripper_result(self, goal: _GripperGoal, stalled, reached) -> GripperCommand.Result:
        """Python bool and float fields: a numpy value would abort the process when serialized."""
        return GripperCommand.Result(
            position=float(self._finger_m()),
            effort=float(self.session.finger_effort_n()),
            stalled=bool(stalled),
            reached_goal=bool(reached),
        )

    def _tick_gripper(self, now_s: float) -> None:
        goal = self.gripper
        if goal is None:
            return
        position = self._finger_m()
        goal.history = [(t, p) for t, p in goal.history if t >= now_s - STALL_TIMEOUT_S] + [(now_s, position)]
        if goal.handle.is_cancel_requested:
            self.gripper = None
            goal.handle.canceled()
            goal.done.set_result(self._gripper_result(goal, stalled=False, reached=False))
            return
        reached = bool(abs(position - goal.target_m) <= GRIPPER_GOAL_TOLERANCE_M)
        span_s = goal.history[-1][0] - goal.history[0][0]
        moved = float(np.ptp([p for _, p in goal.history]))
        stalled = bool(not reached and span_s >= STALL_TIMEOUT_S - 1e-9 and moved < STALL_MOTION_M)
        if reached or stalled:
            self.gripper = None
            goal.handle.succeed()
            goal.done.set_result(self._gripper_result(goal, stalled=stalled, reached=reached))
        elif now_s >= goal.next_feedback_s:
            goal.next_feedback_s = now_s + FEEDBACK_PERIOD_S
            goal.handle.publish_feedback(
                GripperCommand.Feedback(position=float(position), effort=float(self.session.finger_effort_n()))
            )

    def tick(self) -> None:
        now_s = self.sim_time_s()
        self._tick_arm(now_s)
        self._tick_gripper(now_s)

    def close(self) -> None:
        for server in self.servers:
            server.destroy()
