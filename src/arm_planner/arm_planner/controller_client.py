"""plan_node's link to a ros2_control robot: the arm's trajectory as a FollowJointTrajectory goal to
`<arm_controller>/follow_joint_trajectory` (arm joints only) and the gripper's set points as
GripperCommand goals to `<gripper_controller>/gripper_cmd`, each sent when it is due on the node's
clock (arm_planner.execution). A new trajectory replaces the one running, as a joint trajectory
controller does with a new goal; gripper set points not yet sent are dropped with it.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

from control_msgs.action import FollowJointTrajectory, GripperCommand
from rclpy.action import ActionClient
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.duration import Duration
from rclpy.time import Time

from arm_interfaces.action import Manipulate
from arm_planner.execution import split_plan
from arm_planner.messages import trajectory_msg


@dataclass(frozen=True)
class ExecutionReport:
    error_code: int  # FollowJointTrajectory's (0 SUCCESSFUL, negative) or Manipulate.Result.EXECUTION_*
    message: str
    end_ns: int  # node-clock time the motion ended (or was due to), ns


class ControllerClient:
    def __init__(self, node, arm_controller: str, gripper_controller: str, finger_joint: str, max_effort_n: float):
        self.node = node
        self.finger_joint = finger_joint
        self.max_effort_n = float(max_effort_n)
        group = ReentrantCallbackGroup()
        self.arm_action = f"{arm_controller}/follow_joint_trajectory"
        self.gripper_action = f"{gripper_controller}/gripper_cmd"
        self.arm = ActionClient(node, FollowJointTrajectory, self.arm_action, callback_group=group)
        self.gripper = ActionClient(node, GripperCommand, self.gripper_action, callback_group=group)
        self._group = group
        self._done = threading.Condition()
        self._sequence = 0  # of the last arm goal sent
        self._results: dict[int, tuple[int, str]] = {}  # arm goal sequence -> (error code, words)
        self._end_ns = 0  # node-clock time the last trajectory ends
        self._timers = []  # gripper set points not sent yet
        self._gripper_now_m: float | None = None  # the last set point sent
        self._arm_goal = None  # handle of the last accepted arm goal
        self._gripper_sent = 0  # gripper goals sent
        self._gripper_words: dict[int, str] = {}  # gripper goal number -> how it ended

    def missing_servers(self, timeout_s: float) -> list[str]:
        """The controllers' action servers not available within timeout_s (s)."""
        wanted = {self.arm_action: self.arm, self.gripper_action: self.gripper}
        return [name for name, client in wanted.items() if not client.wait_for_server(timeout_sec=timeout_s)]

    def send(self, joint_names, times_s, positions, stamp) -> None:
        """Execute a trajectory (times from `stamp`, a builtin_interfaces Time on the node's clock)."""
        commands = split_plan(joint_names, times_s, positions, self.finger_joint, self._gripper_now_m)
        goal = FollowJointTrajectory.Goal(
            trajectory=trajectory_msg(commands.arm_joint_names, commands.times_s, commands.arm_positions)
        )
        goal.trajectory.header.stamp = stamp
        start_ns = Time.from_msg(stamp).nanoseconds
        with self._done:
            self._sequence += 1
            sequence = self._sequence
            self._end_ns = start_ns + int(1e9 * float(commands.times_s[-1])) if len(commands.times_s) else start_ns
            for timer in self._timers:
                self.node.destroy_timer(timer)
            self._timers = []
        self.arm.send_goal_async(goal).add_done_callback(lambda future: self._on_arm_accepted(sequence, future))
        elapsed_s = 1e-9 * (self.node.get_clock().now().nanoseconds - start_ns)
        for set_point in commands.gripper:
            delay_s = set_point.due_s - elapsed_s
            if delay_s <= 0:
                self._send_gripper(set_point.position_m)
            else:
                self._schedule_gripper(delay_s, set_point.position_m)

    def _schedule_gripper(self, delay_s: float, position_m: float) -> None:
        timer = None

        def fire():
            timer.cancel()
            with self._done:
                if timer not in self._timers:
                    return  # a newer trajectory dropped it
                self._timers.remove(timer)
            self._send_gripper(position_m)

        timer = self.node.create_timer(delay_s, fire, callback_group=self._group)
        with self._done:
            self._timers.append(timer)

    def _send_gripper(self, position_m: float) -> None:
        self._gripper_now_m = position_m
        with self._done:
            self._gripper_sent += 1
            number = self._gripper_sent
        goal = GripperCommand.Goal()
        goal.command.position, goal.command.max_effort = float(position_m), self.max_effort_n
        self.gripper.send_goal_async(goal).add_done_callback(lambda future: self._on_gripper_accepted(number, future))

    def _on_gripper_accepted(self, number: int, future) -> None:
        handle = future.result()
        if not handle.accepted:
            self._record_gripper(number, f"{self.gripper_action} rejected the gripper goal")
            return
        handle.get_result_async().add_done_callback(lambda result: self._on_gripper_result(number, result))

    def _on_gripper_result(self, number: int, future) -> None:
        result = future.result().result
        state = "reached its goal" if result.reached_goal else "stalled" if result.stalled else "stopped"
        self._record_gripper(number, f"gripper {state} at {result.position * 1e3:.1f} mm, {result.effort:.1f} N")

    def _record_gripper(self, number: int, words: str) -> None:
        with self._done:
            if number >= max(self._gripper_words, default=0):  # a preempted goal's late word is dropped
                self._gripper_words = {number: words}
            self._done.notify_all()

    def _gripper_outcome(self) -> str | None:
        """How the last gripper goal ended; None while it runs. Call with the lock held."""
        if self._gripper_sent == 0:
            return "no gripper goal"
        return self._gripper_words.get(self._gripper_sent)

    def _on_arm_accepted(self, sequence: int, future) -> None:
        handle = future.result()
        if not handle.accepted:
            self._record(sequence, Manipulate.Result.EXECUTION_REJECTED, f"{self.arm_action} rejected the goal")
            return
        with self._done:
            if sequence == self._sequence:
                self._arm_goal = handle
        handle.get_result_async().add_done_callback(lambda result: self._on_arm_result(sequence, result))

    def _on_arm_result(self, sequence: int, future) -> None:
        result = future.result().result
        self._record(sequence, int(result.error_code), result.error_string)

    def _record(self, sequence: int, code: int, words: str) -> None:
        with self._done:
            self._results[sequence] = (code, words)
            self._results = {k: v for k, v in self._results.items() if k >= self._sequence}  # bounded
            self._done.notify_all()

    def wait(self, margin_s: float, should_stop=lambda: False) -> ExecutionReport:
        """The last trajectory's result once the controller reports it, with the last gripper goal's
        (waited for until the same deadline); EXECUTION_TIMED_OUT when the arm controller has not
        reported `margin_s` after the trajectory's end on the node's clock."""
        clock = self.node.get_clock()
        with self._done:
            sequence, end_ns = self._sequence, self._end_ns
        deadline_ns = end_ns + Duration(seconds=margin_s).nanoseconds
        while True:
            with self._done:
                late = clock.now().nanoseconds > deadline_ns or should_stop()
                gripper = self._gripper_outcome()
                if sequence in self._results and (gripper is not None or late):
                    code, words = self._results[sequence]
                    gripper = gripper or "the last gripper goal gave no result in time"
                    return ExecutionReport(code, f"{words}; {gripper}", end_ns)
                if late:
                    return ExecutionReport(
                        Manipulate.Result.EXECUTION_TIMED_OUT,
                        f"{self.arm_action} gave no result within {margin_s} s of the trajectory's end",
                        end_ns,
                    )
                self._done.wait(timeout=0.05)

    def cancel(self) -> None:
        """Stop the robot: cancel the running arm goal (the controller holds its position) and drop the
        gripper set points not sent yet."""
        with self._done:
            handle, self._arm_goal = self._arm_goal, None
            for timer in self._timers:
                self.node.destroy_timer(timer)
            self._timers = []
        if handle is not None:
            handle.cancel_goal_async()

    def close(self) -> None:
        with self._done:
            for timer in self._timers:
                self.node.destroy_timer(timer)
            self._timers = []
        self.arm.destroy()
        self.gripper.destroy()
