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
serving. With stream:=true (open loop) the controller executes the plan while it is being planned
(receding horizon, streaming.TrajectoryStream): the first part once stream_lead_s of motion is planned,
the rest in parts every stream_period_s. With replan_period_s > 0 the plan is executed in chunks of
that length and re-planned from the newest joint states and meshes after each chunk (closed loop), the
target found again in newer meshes as the object nearest its last centre.
/diagnostics reports the real-time factor of the last plan (planning wall time / planned motion).
"""

from __future__ import annotations

import threading
import time

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
from arm_planner.mppi import MppiConfig
from arm_planner.planner import DEFAULT_TASK_STEPS, PlannerConfig, resume_point
from arm_planner.scenes import Scene, SceneHistory, follow_target, observed_displacement
from arm_planner.session import ManipulationSession, Outcome
from arm_planner.streaming import TrajectoryStream
from arm_ros.common import RateLimitedErrors, declare, diagnostics_msg, latched_qos, run_node
from arm_ros.conversions import ConversionError
from arm_ros.conversions.stamps import time_ns
from arm_ros.executors import QueueAwareMultiThreadedExecutor


def _planner_config(node: Node) -> tuple[PlannerConfig, float]:
    mppi = MppiConfig(
        steps=declare(node, "steps", 200, "MPPI steps per plan (paper: 200)", 1, 5000),
        num_paths=declare(node, "num_paths", 25, "Sampled paths per step (paper: 25)", 2, 1000),
        horizon=declare(node, "horizon", 5, "Control steps per path (paper: 5)", 1, 100),
        control_dt_s=declare(node, "control_dt_s", 0.02, "Control step, seconds (paper: 0.02)", 0.002, 0.2),
        temperature=declare(node, "temperature", 0.05, "MPPI temperature relative to the return spread", 1e-4, 10.0),
        noise_smoothing=declare(node, "noise_smoothing", 0.8, "AR(1) coefficient of the noise in time", 0.0, 0.99),
        nthread=declare(node, "nthread", 2, "Rollout threads (0: calling thread)", 0, 64),
        seed=declare(node, "seed", 0, "Noise seed", 0, 2**31 - 1),
    )
    config = PlannerConfig(mppi=mppi)
    config.close_steps = declare(node, "close_steps", 75, "Steps the gripper closes for (paper: 75)", 1, 1000)
    config.grasp_lift_goal_m = declare(node, "grasp_lift_goal_m", 0.10, "Lift the grasp reward aims for, m", 0.05, 0.5)
    config.settle_s = declare(node, "settle_s", 0.3, "Twin settling before planning, s", 0.0, 5.0)
    config.sleep_objects = declare(node, "sleep_objects", True, "Let resting twin objects sleep until touched")
    config.rest_creeping_every_step = declare(
        node, "rest_creeping_every_step", False, "Put creeping objects the robot does not touch to rest every step"
    )
    config.sleep_tolerance = declare(
        node, "sleep_tolerance", 0.0, "Twin objects slower than this sleep until touched (0: MuJoCo's 1e-3)", 0.0, 1.0
    )
    config.merge_other_objects = declare(
        node, "merge_other_objects", False, "Cheaper twin: every object but the target as one convex hull"
    )
    config.realtime_factor = declare(
        node,
        "realtime_factor",
        0.9,
        "Planning wall time per planned motion time the path count adapts to (0: always num_paths)",
        0.0,
        100.0,
    )
    config.min_paths = declare(node, "min_paths", 8, "Fewest paths per step when planning in real time", 2, 1000)
    task_steps = {
        task: declare(node, f"{task}_steps", steps, f"Step budget of {task} (0: steps)", 0, 5000)
        for task, steps in DEFAULT_TASK_STEPS.items()
    }
    config.task_steps = {task: steps for task, steps in task_steps.items() if steps}
    config.done_hold_steps = declare(node, "done_hold_steps", 10, "Stop once the goal held this many steps", 0, 1000)
    config.push_hand_speed_m_s = declare(
        node,
        "push_hand_speed_m_s",
        PlannerConfig.push_hand_speed_m_s,
        "Push: the hand's top speed at and near the object, m/s (0: no cap)",
        0.0,
        2.0,
    )
    config.carry_hand_speed_m_s = declare(
        node,
        "carry_hand_speed_m_s",
        PlannerConfig.carry_hand_speed_m_s,
        "Rearrange: the hand's top speed while it holds the object, m/s (0: no cap)",
        0.0,
        2.0,
    )
    config.push_cage = declare(
        node, "push_cage", PlannerConfig.push_cage, "Push: open fingers fore and aft of an object that fits"
    )
    config.push_cage_margin_m = declare(
        node,
        "push_cage_margin_m",
        PlannerConfig.push_cage_margin_m,
        "Push: the cage's clearance to the object each side, m (negative: the fingers close onto it)",
        -0.01,
        0.02,
    )
    config.clear_fingers = declare(
        node, "clear_fingers", PlannerConfig.clear_fingers, "Grasp: turn the fingers off neighbouring objects"
    )
    config.hand_clearance = declare(
        node,
        "hand_clearance",
        PlannerConfig.hand_clearance,
        "Grasp: coming down, keep the open fingers out of the target and the palm off other objects",
    )
    config.grasp_site_search = declare(
        node,
        "grasp_site_search",
        PlannerConfig.grasp_site_search,
        "Grasp: move to where the target's material lies between the fingers when the centre of mass has none",
    )
    config.push_ungraspable = declare(
        node,
        "push_ungraspable",
        PlannerConfig.push_ungraspable,
        "Rearrange: push a target that is wider than the open fingers along every axis",
    )
    config.object_friction = declare(
        node, "object_friction", PlannerConfig.object_friction, "Twin: object-table sliding friction", 0.05, 2.0
    )
    timestep = declare(node, "twin_timestep_s", 0.01, "Twin physics step, s (divides control_dt_s)", 0.001, 0.02)
    return config, timestep


class PlanNode(Node):
    def __init__(self, **node_options):
        super().__init__("plan_node", **node_options)
        config, timestep = _planner_config(self)
        self.execute_plans = declare(self, "execute", True, "Send the planned trajectory to the controllers")
        self.controller_interface = declare(
            self,
            "controller_interface",
            "ros2_control",
            "ros2_control: FollowJointTrajectory and GripperCommand goals; topic: JointTrajectory on "
            "arm/joint_trajectory (no execution feedback)",
            choices=["ros2_control", "topic"],
        )
        arm_controller = declare(
            self, "arm_controller", "arm_controller", "Joint trajectory controller: <name>/follow_joint_trajectory"
        )
        gripper_controller = declare(
            self, "gripper_controller", "gripper_controller", "Gripper action controller: <name>/gripper_cmd"
        )
        gripper_max_effort_n = declare(
            self, "gripper_max_effort_n", 70.0, "GripperCommand max_effort, N (0: the controller's)", 0.0, 1000.0
        )
        self.execution_margin_s = declare(
            self,
            "execution_margin_s",
            5.0,
            "Wait this long past the trajectory's end for the arm controller's result, s",
            0.0,
            600.0,
        )
        self.observe_timeout_s = declare(
            self,
            "observe_timeout_s",
            15.0,
            "After the motion, wait this long for meshes of a newer frame to observe the target (0: do not), s",
            0.0,
            600.0,
        )
        self.replan_period_s = declare(
            self, "replan_period_s", 0.0, "Closed loop: execute this long, then re-plan (0: open loop)", 0.0, 60.0
        )
        self.stream = declare(self, "stream", True, "Open loop: execute the plan while planning the rest")
        self.stream_lead_s = declare(
            self, "stream_lead_s", 0.5, "Stream: motion planned before the first part, s", 0.0, 60.0
        )
        self.stream_period_s = declare(self, "stream_period_s", 0.2, "Stream: motion planned per part, s", 0.0, 60.0)
        self.execute_unmet = declare(
            self,
            "execute_unmet",
            True,
            "Publish a plan that did not meet the task in the twin (false: hold it back and say so in the "
            "result; needs stream false and replan_period_s 0, where nothing moves before the plan is done)",
        )
        if not self.execute_unmet and (self.stream or self.replan_period_s > 0):
            raise ValueError(
                "execute_unmet false needs stream false and replan_period_s 0: a streamed or re-planned "
                "motion is under way before the plan is done"
            )
        self.max_replans = declare(self, "max_replans", 10, "Closed loop: re-plans per goal at most", 0, 1000)
        self.feedback_every = declare(self, "feedback_every_steps", 10, "Publish feedback every N steps", 1, 1000)
        self.joint_state_timeout_s = declare(
            self, "joint_state_timeout_s", 2.0, "Refuse goals when joint states are older than this, s", 0.0, 3600.0
        )
        self.max_object_size_m = declare(
            self, "max_object_size_m", 1.0, "Leave objects larger than this out of the twin, m", 0.01, 100.0
        )
        self.replan_target_radius_m = declare(
            self,
            "replan_target_radius_m",
            0.15,
            "Closed loop: newer meshes' target is the object nearest the last one's centre, within this, m",
            0.0,
            10.0,
        )
        history = declare(self, "scene_history", 20, "/arm/meshes arrays kept for goals naming one by stamp", 1, 1000)
        base_xyz = declare(
            self,
            "robot_base_xyz_m",
            [-0.55, 0.0, 0.0],
            "World position of the robot base (as segmentation_node's); the twin stands it on the table at x, y",
        )
        if len(base_xyz) != 3 or not all(np.isfinite(v) for v in base_xyz):
            raise ValueError(f"robot_base_xyz_m must be 3 finite values, got {list(base_xyz)}")
        self.session = ManipulationSession(config, timestep, robot_base_world=(float(base_xyz[0]), float(base_xyz[1])))
        self.finger_joint = self.session.robot.trajectory_joint_names[-1]
        self.controllers = None
        if self.controller_interface == "ros2_control":
            self.controllers = ControllerClient(
                self, arm_controller, gripper_controller, self.finger_joint, gripper_max_effort_n
            )
        self.errors = RateLimitedErrors(self.get_logger())

        self._lock = threading.Lock()
        self._scenes = SceneHistory(history)  # the last /arm/meshes arrays, by stamp
        self._joints = None  # (arm_q, opening, node-clock ns at receipt) from the latest valid /joint_states
        self._joint_error = ""
        self._busy = False
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
        self.get_logger().info(
            f"plan_node ready: {config.mppi.steps} steps x {config.mppi.num_paths} paths x horizon "
            f"{config.mppi.horizon} at {config.mppi.control_dt_s} s, twin step {timestep} s"
        )

    # --- inputs ------------------------------------------------------------------------------
    def on_meshes(self, msg: ReconstructedObjectArray) -> None:
        try:
            objects, table_height_m, dropped = twin_objects_from_msg(msg, self.max_object_size_m)
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
        if self.joint_state_timeout_s > 0 and age_s > self.joint_state_timeout_s:
            return None, f"joint states are older than {self.joint_state_timeout_s} s"
        return joints, ""

    def _goal_scene(self, goal) -> tuple[Scene | None, str]:
        """The meshes the goal's target id refers to, or why there are none."""
        stamp_ns = time_ns(goal.meshes_stamp)
        with self._lock:
            scene, held = self._scenes.stamped(stamp_ns), self._scenes.stamps_ns()
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
        followed = follow_target(scene, target_id, latest, self.replan_target_radius_m)
        if followed is None:
            self.errors.error(
                "replan target", f"target {target_id} not found in newer meshes; re-planning on the older ones"
            )
            return scene, target_id
        return latest, followed

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
        if part is not None and self.execute_plans:
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
            if step % self.feedback_every == 0 or step == total:
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

    def _publish(self, outcome: Outcome, count: int | None = None, publish: bool = True) -> JointTrajectory:
        """The outcome's first count points as a trajectory, sent to the controller when execute and
        publish are both true."""
        result = outcome.result
        n = len(result.times_s) if count is None else count
        msg = trajectory_msg(result.joint_names, result.times_s[:n], result.joint_positions[:n])
        msg.header.stamp = self.get_clock().now().to_msg()
        if self.execute_plans and publish and n:
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
        result = Manipulate.Result(
            success=bool(outcome.success),
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
        if self.replan_period_s <= 0 and self.stream:
            stream = TrajectoryStream(self.session.config.mppi.control_dt_s, self.stream_lead_s, self.stream_period_s)
            outcome = self._plan_once(goal_handle, task, goal, scene, target_id, None, None, stream)
            if not outcome.planned:
                return outcome, JointTrajectory()
            result = outcome.result
            return outcome, trajectory_msg(result.joint_names, result.times_s, result.joint_positions)
        outcome = self._plan_once(goal_handle, task, goal, scene, target_id, None, None)
        if not outcome.planned:
            return outcome, JointTrajectory()
        if self.replan_period_s <= 0:
            held_back = not outcome.success and not self.execute_unmet
            if held_back:
                outcome.message += "; not executed (execute_unmet is false)"
            return outcome, self._publish(outcome, publish=not held_back)
        start_com, resume = outcome.start_com_world, None
        executed_times, executed_positions, executed_s = [], [], 0.0  # the chunks one after another
        for _ in range(self.max_replans + 1):
            result = outcome.result
            chunk = int(np.searchsorted(result.times_s, self.replan_period_s, side="right"))
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
            self.execution_margin_s, should_stop=lambda: goal_handle.is_cancel_requested or not rclpy.ok()
        )
        if goal_handle.is_cancel_requested:
            self.controllers.cancel()
        result.controller_error_code, result.controller_message = report.error_code, report.message
        if report.error_code != 0 or self.observe_timeout_s <= 0 or self._goal_start is None:
            return
        scene, target_id = self._goal_start
        newer = self._scene_after(report, self.observe_timeout_s)
        if newer is None:
            result.controller_message += f"; no meshes of a frame after the motion within {self.observe_timeout_s} s"
            return
        if task == "grasp":
            expected = (0.0, 0.0, self.session.config.grasp_lift_goal_m)
        else:
            expected = (goal.goal_displacement.x, goal.goal_displacement.y, goal.goal_displacement.z)
        moved = observed_displacement(scene, target_id, newer, expected, self.replan_target_radius_m)
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
        values = {
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
