"""plan_node: action /arm/manipulate -> MPPI plan in the MuJoCo twin -> the robot's controllers.

The plan goes to a ros2_control robot as a FollowJointTrajectory goal for the arm and GripperCommand
goals for the gripper (controller_client; controller_interface ros2_control), or as one JointTrajectory
of arm and finger joints on /arm/joint_trajectory (topic). With ros2_control the goal's result carries
the arm controller's error code and, once a frame taken after the motion shows the target, its
observed displacement.

Subscribes /arm/meshes (reliable, transient-local) and keeps the last scene_history arrays, so a goal
plans on the array its target id was read from (goal.meshes_stamp; zero: the latest). Keeps only the
latest /joint_states. One goal is served at a time; a goal arriving while another plans is rejected. Every refusal
(no meshes, unknown target, degenerate mesh, goal out of reach, non-finite joint states, twin
compilation failure, planning error) aborts the goal with the reason in the result; the node keeps
serving. The `execution` mode (node_config.EXECUTION_MODES) says what reaches the robot: nothing
(plan_only); the finished plan if it met the task in the twin (execute); the plan in parts while it is
being planned (stream, receding horizon: streaming.TrajectoryStream); or chunks of replan_period_s,
each re-planned from the newest joint states and meshes, the target found again as the object nearest
its last centre (replan, closed loop).
/diagnostics reports the real-time factor of the last plan (planning wall time / planned motion).
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.duration import Duration
from rclpy.node import Node
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from arm_interfaces.action import Manipulate
from arm_interfaces.msg import ReconstructedObjectArray
from arm_planner.controller_client import ControllerClient, ExecutionReport
from arm_planner.messages import TASK_NAMES, joint_state_arrays, trajectory_msg, twin_objects_from_msg
from arm_planner.node_config import PlanNodeConfig
from arm_planner.planner import resume_point
from arm_planner.scenes import Scene, SceneHistory, follow_target, observed_displacement
from arm_planner.session import ManipulationSession, Outcome
from arm_planner.streaming import TrajectoryStream
from arm_ros.common import RateLimitedErrors, declare_settings, diagnostics_msg, latched_qos, run_node
from arm_ros.conversions import ConversionError
from arm_ros.conversions.stamps import time_ns
from arm_ros.executors import QueueAwareMultiThreadedExecutor

# A dry run's plan may be executed this long after it was made (a client choosing among the demo's
# 10 candidates dry-runs them for up to about a minute) ...
DRY_RUN_VALID_S = 120.0
DRY_RUN_JOINT_TOLERANCE_RAD = 0.01  # ... with every arm joint still this near where it started
DRY_RUN_GRIPPER_TOLERANCE_M = 0.002
DRY_RUNS_KEPT = 10  # the plans of the last this many dry runs that met the task are kept
# A client that takes its target from the /arm/meshes array it has just received may send the goal
# before that array reached this node: a goal stamped newer than every held array waits this long
# (wall clock) for it. With segmentation and reconstruction busy on 2 cores an array reached the
# demo's client more than 2 s before it reached this node.
MESHES_ARRIVAL_WAIT_S = 10.0


@dataclass
class DryRun:
    """A plan_only goal's request, the robot state it was planned from and its outcome."""

    request: tuple
    arm_q: np.ndarray
    opening_m: float
    outcome: Outcome
    made_s: float  # time.monotonic()

    def repeated_by(self, request: tuple, joints) -> bool:
        """Whether a goal for `request` with the robot at `joints` ((arm_q, opening, stamp) or None) may
        execute this plan: the same request, soon enough, the robot where it was."""
        if request != self.request or joints is None or time.monotonic() - self.made_s > DRY_RUN_VALID_S:
            return False
        arm_q, opening_m = joints[0], joints[1]
        return bool(
            np.max(np.abs(np.asarray(arm_q) - self.arm_q)) <= DRY_RUN_JOINT_TOLERANCE_RAD
            and abs(float(opening_m) - self.opening_m) <= DRY_RUN_GRIPPER_TOLERANCE_M
        )


class PlanNode(Node):
    def __init__(self, **node_options):
        super().__init__("plan_node", **node_options)
        self.config = config = declare_settings(self, PlanNodeConfig())
        base_xyz = config.robot_base_xyz_m
        if not all(np.isfinite(v) for v in base_xyz):
            raise ValueError(f"robot_base_xyz_m must be 3 finite values, got {list(base_xyz)}")
        self.session = ManipulationSession(
            config.planner, config.twin_timestep_s, robot_base_world=(float(base_xyz[0]), float(base_xyz[1]))
        )
        self.finger_joint = self.session.robot.trajectory_joint_names[-1]
        self.controllers = None
        if config.controller_interface == "ros2_control":
            self.controllers = ControllerClient(
                self, config.arm_controller, config.gripper_controller, self.finger_joint, config.gripper_max_effort_n
            )
        self.errors = RateLimitedErrors(self.get_logger())

        self._lock = threading.Lock()
        self._scenes = SceneHistory(config.scene_history)  # the last /arm/meshes arrays, by stamp
        self._joints = None  # (arm_q, opening, node-clock ns at receipt) from the latest valid /joint_states
        self._joint_error = ""
        self._busy = False
        # the plans of the last DRY_RUNS_KEPT plan_only goals that met the task, by request
        self._dry_runs: OrderedDict[tuple, DryRun] = OrderedDict()
        self.goals = self.refusals = self.meshes_received = self.meshes_rejected = 0
        self.plan_figures = {}  # timing of the last plan, for /diagnostics

        inputs = MutuallyExclusiveCallbackGroup()
        self.create_subscription(
            ReconstructedObjectArray, "arm/meshes", self.on_meshes, latched_qos(), callback_group=inputs
        )
        self.create_subscription(JointState, "joint_states", self.on_joint_states, 1, callback_group=inputs)
        self.pub_trajectory = self.create_publisher(JointTrajectory, "arm/joint_trajectory", 1)
        self.pub_diag = self.create_publisher(DiagnosticArray, "diagnostics", 10)
        self.create_timer(1.0, self.publish_diagnostics, callback_group=inputs)
        self.action_server = ActionServer(
            self,
            Manipulate,
            "arm/manipulate",
            execute_callback=self.execute,
            goal_callback=self.on_goal,
            cancel_callback=lambda _: CancelResponse.ACCEPT,
            callback_group=ReentrantCallbackGroup(),
        )
        mppi = config.planner.mppi
        self.get_logger().info(
            f"plan_node ready ({config.execution}): {mppi.steps} steps x {mppi.num_paths} paths x horizon "
            f"{mppi.horizon} at {mppi.control_dt_s} s, twin step {config.twin_timestep_s} s"
        )

    # --- inputs ------------------------------------------------------------------------------
    def on_meshes(self, msg: ReconstructedObjectArray) -> None:
        try:
            objects, table_height_m, dropped = twin_objects_from_msg(msg, self.config.max_object_size_m)
        except ConversionError as error:
            self.meshes_rejected += 1
            self.errors.error("meshes", f"ignoring malformed /arm/meshes: {error}")
            return
        for object_id, reason in dropped.items():
            self.errors.error(f"object {object_id}", f"object {object_id} left out of the twin: {reason}")
        with self._lock:
            self._scenes.add(Scene(objects, table_height_m, time_ns(msg.header.stamp), dropped))
            self.meshes_received += 1

    def on_joint_states(self, msg: JointState) -> None:
        try:
            arm_q, opening = joint_state_arrays(msg, self.session.robot.arm_joints, self.finger_joint)
        except ConversionError as error:
            with self._lock:
                self._joint_error = str(error)
            self.errors.error("joint_states", f"ignoring joint states: {error}")
            return
        with self._lock:
            self._joints = (arm_q, opening, self.get_clock().now().nanoseconds)
            self._joint_error = ""

    # --- action ------------------------------------------------------------------------------
    def on_goal(self, goal) -> GoalResponse:
        with self._lock:
            if self._busy:
                self.errors.error("busy", "rejecting a manipulation goal: another one is being served")
                return GoalResponse.REJECT
            self._busy = True
        return GoalResponse.ACCEPT

    def _robot_state(self):
        with self._lock:
            joints, error = self._joints, self._joint_error
        if error:
            return None, f"latest joint states are invalid: {error}"
        if joints is None:
            return None, "no joint states received yet"
        age_s = 1e-9 * (self.get_clock().now().nanoseconds - joints[2])  # ROS time: simulated with use_sim_time
        if self.config.joint_state_timeout_s > 0 and age_s > self.config.joint_state_timeout_s:
            return None, f"joint states are older than {self.config.joint_state_timeout_s} s"
        return joints, ""

    def _goal_scene(self, goal) -> tuple[Scene | None, str]:
        """The meshes the goal's target id refers to, or why there are none."""
        stamp_ns = time_ns(goal.meshes_stamp)
        deadline = time.monotonic() + MESHES_ARRIVAL_WAIT_S
        while True:
            with self._lock:
                scene, held = self._scenes.stamped(stamp_ns), self._scenes.stamps_ns()
            in_flight = stamp_ns > max(held, default=-1)
            if scene is not None or not in_flight or time.monotonic() >= deadline:
                break
            time.sleep(0.02)
        if scene is not None:
            return scene, ""
        if not held:
            return None, "no reconstructed objects received yet (/arm/meshes)"
        return None, (
            f"no /arm/meshes array stamped {stamp_ns} ns is held (the last {len(held)} span "
            f"{min(held)}-{max(held)} ns); take target_id from a recent array"
        )

    def _newer_scene(self, scene: Scene, target_id: int) -> tuple[Scene, int]:
        """Closed loop: the latest meshes and the target's id in them, or the given ones if the target
        cannot be found there."""
        with self._lock:
            latest = self._scenes.latest()
        if latest is scene:
            return scene, target_id
        followed = follow_target(scene, target_id, latest, self.config.replan_target_radius_m)
        if followed is None:
            self.errors.error(
                "replan target", f"target {target_id} not found in newer meshes; re-planning on the older ones"
            )
            return scene, target_id
        return latest, followed

    @staticmethod
    def _displacement(goal) -> tuple[float, float, float]:
        return tuple(
            round(float(v), 6) for v in (goal.goal_displacement.x, goal.goal_displacement.y, goal.goal_displacement.z)
        )

    def _send(self, joint_names, times_s, positions, stamp) -> None:
        """Execute a trajectory whose times count from `stamp` (the node's clock)."""
        self._sent = True
        if self.controllers is not None:
            self.controllers.send(joint_names, times_s, positions, stamp)
        else:
            msg = trajectory_msg(joint_names, times_s, positions)
            msg.header.stamp = stamp
            self.pub_trajectory.publish(msg)

    def _stream_part(self, stream: TrajectoryStream, joint_names) -> None:
        now = self.get_clock().now()  # one reading: the part's times count from its stamp
        part = stream.part(1e-9 * now.nanoseconds)
        if part is not None:
            self._send(joint_names, part.times_s, part.positions, now.to_msg())

    def _plan_once(
        self,
        goal_handle,
        task: str,
        goal,
        scene: Scene,
        target_id: int,
        resume: tuple | None,
        start_com,
        stream: TrajectoryStream | None = None,
    ) -> Outcome:
        joints, problem = self._robot_state()
        if problem:
            return Outcome(False, problem)
        self.session.set_objects(scene.objects, scene.table_height_m)
        feedback = Manipulate.Feedback()

        def on_step(step: int, total: int, state: str, error_m: float) -> None:
            if step % self.config.feedback_every_steps == 0 or step == total:
                feedback.step, feedback.total_steps, feedback.state = step, total, state
                feedback.predicted_error_m = float(error_m)
                goal_handle.publish_feedback(feedback)

        joint_names = self.session.robot.trajectory_joint_names

        def on_control(position: np.ndarray) -> None:
            stream.add(position)
            if stream.due():
                self._stream_part(stream, joint_names)

        displacement = (goal.goal_displacement.x, goal.goal_displacement.y, goal.goal_displacement.z)
        started = time.perf_counter()
        outcome = self.session.request(
            task,
            target_id,
            displacement,
            float(goal.tolerance_m),
            joints[0],
            joints[1],
            feedback=on_step,
            should_stop=lambda: goal_handle.is_cancel_requested or not rclpy.ok(),
            start_com_world=start_com,
            resume_state=resume[0] if resume else None,
            resume_steps_in_state=resume[1] if resume else 0,
            stream=on_control if stream is not None else None,
        )
        plan_s = time.perf_counter() - started
        if stream is not None:
            self._stream_part(stream, joint_names)  # the rest of the plan
        if outcome.result is not None and len(outcome.result.step_ms):
            result = outcome.result
            motion_s = float(result.times_s[-1]) if len(result.times_s) else float("nan")
            self.plan_figures = {
                "last_plan_twin_objects": outcome.twin_objects,  # twin_objects: the latest /arm/meshes
                "last_plan_s": plan_s,
                "last_motion_s": motion_s,
                "realtime_factor": plan_s / motion_s,
                "mppi_steps_last": len(result.step_ms),
                "mppi_step_ms_last": float(result.step_ms[-1]),
                "mppi_step_ms_median": float(np.median(result.step_ms)),
                "mppi_step_ms_p90": float(np.percentile(result.step_ms, 90)),
                "mppi_step_cpu_ms_median": float(np.median(result.step_cpu_ms)),
                "mppi_paths_median": float(np.median(result.step_paths)),
                "mppi_paths_min": float(np.min(result.step_paths)),
                "stream_parts": stream.parts if stream is not None else 0,
                "stream_stall_s": stream.stall_s if stream is not None else 0.0,
            }
        return outcome

    def _publish(self, outcome: Outcome, count: int | None = None, send: bool = True) -> JointTrajectory:
        """The outcome's first count points as a trajectory, sent to the controllers when send is true."""
        result = outcome.result
        n = len(result.times_s) if count is None else count
        msg = trajectory_msg(result.joint_names, result.times_s[:n], result.joint_positions[:n])
        msg.header.stamp = self.get_clock().now().to_msg()
        if send and n:
            self._send(result.joint_names, result.times_s[:n], result.joint_positions[:n], msg.header.stamp)
        return msg

    def execute(self, goal_handle):
        try:
            return self._execute(goal_handle)
        except Exception as error:  # the node must keep serving whatever happens inside one goal
            self.errors.error("execute", f"goal failed: {type(error).__name__}: {error}")
            goal_handle.abort()
            return Manipulate.Result(
                success=False, message=f"internal error: {type(error).__name__}: {error}", final_error_m=float("nan")
            )
        finally:
            with self._lock:
                self._busy = False

    def _execute(self, goal_handle):
        goal = goal_handle.request
        self.goals += 1
        self._sent, self._goal_start = False, None
        task = TASK_NAMES.get(int(goal.task))
        if task is None:
            outcome = Outcome(False, f"unknown task {goal.task}; expected one of {sorted(TASK_NAMES)}")
        else:
            outcome, trajectory = self._run(goal_handle, task, goal)
        if not outcome.planned:
            self.refusals += 1
            self.errors.error("refused", f"manipulation goal refused: {outcome.message}")
            goal_handle.abort()
            return Manipulate.Result(success=False, message=outcome.message, final_error_m=float("nan"))
        replays = outcome.result.replays if outcome.result is not None else None
        result = Manipulate.Result(
            success=bool(outcome.success),
            held_in_twin=bool(outcome.result is not None and outcome.result.held),
            perturbed_twins=int(replays.twins) if replays else 0,
            perturbed_twins_met=int(replays.met) if replays else 0,
            message=outcome.message,
            final_error_m=float(outcome.final_error_m),
            trajectory=trajectory,
            controller_error_code=Manipulate.Result.EXECUTION_NOT_SENT,
            controller_message="not executed",
        )
        if self._sent:
            self._execution_result(goal_handle, task, goal, result)
        if goal_handle.is_cancel_requested:
            goal_handle.canceled()
            result.message = "canceled: " + result.message
        else:
            goal_handle.succeed()
        return result

    def _run(self, goal_handle, task: str, goal):
        scene, problem = self._goal_scene(goal)
        if scene is None:
            return Outcome(False, problem), JointTrajectory()
        target_id = int(goal.target_id)
        self._goal_start = (scene, target_id)
        mode = "plan_only" if goal.plan_only else self.config.execution
        request = (task, target_id, scene.stamp_ns, *self._displacement(goal), round(float(goal.tolerance_m), 6))
        if mode != "plan_only":
            dry_run = self._dry_runs.pop(request, None)
            self._dry_runs.clear()  # the robot moves: every other dry run's start state is gone
            if dry_run is not None and dry_run.repeated_by(request, self._robot_state()[0]):
                outcome = dry_run.outcome
                outcome.message += "; executing the plan of the dry run"
                return outcome, self._publish(outcome, send=True)
        if mode == "stream":
            stream = TrajectoryStream(
                self.session.config.mppi.control_dt_s, self.config.stream_lead_s, self.config.stream_period_s
            )
            outcome = self._plan_once(goal_handle, task, goal, scene, target_id, None, None, stream)
            if not outcome.planned:
                return outcome, JointTrajectory()
            result = outcome.result
            return outcome, trajectory_msg(result.joint_names, result.times_s, result.joint_positions)
        outcome = self._plan_once(goal_handle, task, goal, scene, target_id, None, None)
        if not outcome.planned:
            return outcome, JointTrajectory()
        if mode == "plan_only":
            joints = self._robot_state()[0]
            self._dry_runs.pop(request, None)
            if outcome.success and joints is not None:
                self._dry_runs[request] = DryRun(request, joints[0], joints[1], outcome, time.monotonic())
                while len(self._dry_runs) > DRY_RUNS_KEPT:
                    self._dry_runs.popitem(last=False)
            return outcome, self._publish(outcome, send=False)
        if mode == "execute":
            if not outcome.success:
                outcome.message += "; not executed: the plan did not meet the task in the twin"
            return outcome, self._publish(outcome, send=outcome.success)
        start_com, resume = outcome.start_com_world, None
        executed_times, executed_positions, executed_s = [], [], 0.0  # the chunks one after another
        for _ in range(self.config.max_replans + 1):
            result = outcome.result
            chunk = int(np.searchsorted(result.times_s, self.config.replan_period_s, side="right"))
            last = chunk >= len(result.times_s) or goal_handle.is_cancel_requested
            n = len(result.times_s) if last else chunk
            self._publish(outcome, n)
            executed_times.append(executed_s + result.times_s[:n])
            executed_positions.append(result.joint_positions[:n])
            executed_s += float(result.times_s[n - 1]) if n else 0.0
            if last:
                break
            # the executed prefix runs on the controller's (the sim's) clock: wait on the node's clock,
            # which follows /clock with use_sim_time:=true; other callbacks run on the executor's threads
            waited = self.get_clock().sleep_for(Duration(seconds=float(result.times_s[chunk - 1])))
            if not waited:  # shutdown
                break
            resume = resume_point(result.states, chunk)
            scene, target_id = self._newer_scene(scene, target_id)
            replanned = self._plan_once(goal_handle, task, goal, scene, target_id, resume, start_com)
            if not replanned.planned:
                self.errors.error("replan", f"re-planning failed, keeping the executed prefix: {replanned.message}")
                break
            outcome = replanned
        if not executed_times:
            return outcome, JointTrajectory()
        executed = trajectory_msg(
            outcome.result.joint_names, np.concatenate(executed_times), np.concatenate(executed_positions)
        )
        return outcome, executed

    # --- execution ---------------------------------------------------------------------------
    def _execution_result(self, goal_handle, task: str, goal, result) -> None:
        """Fill `result` with how the execution went: the arm controller's result and the target's
        observed displacement."""
        if self.controllers is None:
            result.controller_error_code = Manipulate.Result.EXECUTION_UNCONFIRMED
            result.controller_message = "sent on arm/joint_trajectory (no controller feedback)"
            return
        goal_handle.publish_feedback(Manipulate.Feedback(state="executing", executing=True))
        report = self.controllers.wait(
            self.config.execution_margin_s, should_stop=lambda: goal_handle.is_cancel_requested or not rclpy.ok()
        )
        if goal_handle.is_cancel_requested:
            self.controllers.cancel()
        result.controller_error_code, result.controller_message = report.error_code, report.message
        if report.error_code != 0 or self.config.observe_timeout_s <= 0 or self._goal_start is None:
            return
        scene, target_id = self._goal_start
        newer = self._scene_after(report, self.config.observe_timeout_s)
        if newer is None:
            result.controller_message += (
                f"; no meshes of a frame after the motion within {self.config.observe_timeout_s} s"
            )
            return
        requested = (goal.goal_displacement.x, goal.goal_displacement.y, goal.goal_displacement.z)
        expected = self.session.goal_displacement(task, requested)
        moved = observed_displacement(scene, target_id, newer, expected, self.config.replan_target_radius_m)
        if moved is None:
            result.controller_message += "; the target was not found in the meshes after the motion"
            return
        result.displacement_observed = True
        result.observed_displacement.x, result.observed_displacement.y, result.observed_displacement.z = (
            float(v) for v in moved
        )

    def _scene_after(self, report: ExecutionReport, timeout_s: float) -> Scene | None:
        """The first meshes of a frame stamped after the motion ended, waiting up to timeout_s (wall s)."""
        deadline = time.monotonic() + timeout_s
        while rclpy.ok() and time.monotonic() < deadline:
            with self._lock:
                latest = self._scenes.latest()
            if latest is not None and latest.stamp_ns > report.end_ns:
                return latest
            time.sleep(0.1)
        return None

    # --- diagnostics -------------------------------------------------------------------------
    def publish_diagnostics(self) -> None:
        with self._lock:
            latest = self._scenes.latest()
            ids = sorted(o.id for o in latest.objects) if latest else []
            busy = self._busy
        objects = len(ids)
        _, joint_problem = self._robot_state()
        values = {
            "joint_states": joint_problem or "ok",
            "goals": self.goals,
            "refusals": self.refusals,
            "busy": busy,
            "twin_objects": objects,
            "twin_object_ids": " ".join(map(str, ids)),
            "twin_builds": self.session.twin_builds,
            "meshes_received": self.meshes_received,
            "meshes_rejected": self.meshes_rejected,
        } | self.plan_figures
        level = DiagnosticStatus.OK if objects else DiagnosticStatus.WARN
        message = "ok" if objects else "waiting for /arm/meshes"
        self.pub_diag.publish(diagnostics_msg(self, "planner", values, level, message))

    def close(self) -> None:
        if self.controllers is not None:
            self.controllers.close()
        self.action_server.destroy()
        self.session.close()


def main(args=None) -> int:
    return run_node(PlanNode, args, executor_factory=lambda: QueueAwareMultiThreadedExecutor(num_threads=4))


if __name__ == "__main__":
    raise SystemExit(main())
