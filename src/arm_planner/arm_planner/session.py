"""Manipulation requests against the latest reconstructed scene: validation, twin caching, planning.

The ROS node and the benchmark both go through ManipulationSession, so every bad input (unknown
target, degenerate mesh, goal out of reach, non-finite joint states, a twin that fails to compile)
ends as an Outcome with a reason instead of an exception.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from arm_planner.planner import (
    DEFAULT_TOLERANCE_M,
    Feedback,
    Observe,
    Planner,
    PlannerConfig,
    PlanRequest,
    PlanResult,
    Stream,
)
from arm_planner.robot_spec import RobotSpec
from arm_planner.tasks import TASK_GRASP, TASKS
from arm_planner.tasks.base import TaskInfeasible
from arm_planner.twin import Twin, TwinError, TwinObject, geometry_signature, panda_robot_spec

# Panda: shoulder (joint 2) 0.333 m above the base; shoulder -> wrist (joint 6) at most ~0.80 m
# (0.316 + sqrt(0.384^2 + 0.0825^2) + 0.088). A top-down grasp puts the wrist ~0.21 m above the TCP.
SHOULDER_HEIGHT_M = 0.333
WRIST_ABOVE_TCP_M = 0.21
REACH_M = 0.80


@dataclass
class Outcome:
    """What a request produced. planned: a trajectory exists (possibly predicted to fail). infeasible:
    refused because the robot cannot do the task at all (out of its reach, or too wide for its gripper)."""

    success: bool
    message: str
    final_error_m: float = float("nan")
    planned: bool = False
    result: PlanResult | None = None
    twin_objects: int = 0
    skipped: dict[int, str] = field(default_factory=dict)
    start_com_world: np.ndarray | None = None
    infeasible: bool = False

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.result.joint_names if self.result else ()


def reach_problem(point, robot_base_xy, table_height_m: float) -> str | None:
    """Why the hand cannot bring its grasp point to `point` (world, m) from above, or None: the wrist,
    WRIST_ABOVE_TCP_M over it, would be beyond REACH_M from the shoulder, or the point is under the table."""
    point = np.asarray(point, dtype=np.float64)
    shoulder = np.array([*robot_base_xy, table_height_m + SHOULDER_HEIGHT_M])
    distance = float(np.linalg.norm(point + np.array([0.0, 0.0, WRIST_ABOVE_TCP_M]) - shoulder))
    if distance > REACH_M:
        return (
            f"{np.round(point, 3).tolist()} needs the wrist {distance:.2f} m from the shoulder (reach {REACH_M:.2f} m)"
        )
    if point[2] < table_height_m - 0.01:
        return f"{np.round(point, 3).tolist()} is below the table"
    return None


def refused(message: str) -> Outcome:
    return Outcome(False, message)


class ManipulationSession:
    """Holds the latest objects, a twin and a planner (rebuilt only when the geometry changes)."""

    def __init__(
        self,
        config: PlannerConfig | None = None,
        twin_timestep_s: float = 0.01,
        robot: RobotSpec | None = None,
        robot_base_world: tuple[float, float] = (-0.55, 0.0),
    ):
        self.config = config or PlannerConfig()
        self.twin_timestep_s = float(twin_timestep_s)
        self.robot = robot or panda_robot_spec()
        self.robot_base_xy = np.asarray(robot_base_world, dtype=np.float64)
        self.objects: list[TwinObject] | None = None
        self.table_height_m = 0.0
        self.twin: Twin | None = None
        self.planner: Planner | None = None
        self.twin_builds = 0

    def set_objects(self, objects: list[TwinObject], table_height_m: float) -> None:
        self.objects = list(objects)
        self.table_height_m = float(table_height_m)

    def close(self) -> None:
        if self.planner is not None:
            self.planner.close()
            self.planner = None

    def _ensure_twin(self, target_id: int) -> None:
        objects = self.objects
        signature = geometry_signature(objects, self.table_height_m)
        if self.twin is not None and self.twin.signature == signature:
            return
        self.close()
        self.twin = None
        self.twin = Twin(
            objects,
            self.table_height_m,
            self.twin_timestep_s,
            self.robot,
            self.config.twin_overlap_exclude_m,
            self.config.object_friction,
            self.robot_base_xy,
        )
        self.planner = Planner(self.twin.model, self.robot, self.config)
        self.twin_builds += 1

    def goal_displacement(self, task: str, displacement) -> np.ndarray:
        """Where the task moves the target, m: a grasp lifts it by grasp_lift_goal_m whatever the goal says."""
        if task == TASK_GRASP:
            return np.array([0.0, 0.0, self.config.grasp_lift_goal_m])
        return np.asarray(displacement, dtype=np.float64)

    def _reach_problem(self, point: np.ndarray) -> str | None:
        return reach_problem(point, self.robot_base_xy, self.table_height_m)

    def request(
        self,
        task: str,
        target_id: int,
        goal_displacement_m=(0.0, 0.0, 0.0),
        tolerance_m: float = 0.0,
        arm_q=None,
        gripper_opening_m: float | None = None,
        feedback: Feedback | None = None,
        should_stop: Callable[[], bool] | None = None,
        start_com_world=None,
        resume_state: str | None = None,
        resume_steps_in_state: int = 0,
        observe: Observe | None = None,
        stream: Stream | None = None,
    ) -> Outcome:
        """Plan `task` on object `target_id` from the given robot state; never raises on bad input."""
        if task not in TASKS:
            return refused(f"unknown task {task!r}; expected one of {list(TASKS)}")
        if self.objects is None:
            return refused("no reconstructed objects received yet")
        if arm_q is None or gripper_opening_m is None:
            return refused("no joint states received yet")
        arm_q = np.asarray(arm_q, dtype=np.float64)
        if arm_q.shape != (len(self.robot.arm_joints),) or not np.all(np.isfinite(arm_q)):
            return refused(f"joint states are not {len(self.robot.arm_joints)} finite angles: {arm_q.tolist()}")
        if not np.isfinite(gripper_opening_m):
            return refused("gripper opening is not finite")
        displacement = np.asarray(goal_displacement_m, dtype=np.float64)
        if displacement.shape != (3,) or not np.all(np.isfinite(displacement)):
            return refused("goal displacement is not 3 finite numbers")
        if not np.isfinite(tolerance_m) or tolerance_m < 0:
            return refused(f"tolerance {tolerance_m} must be >= 0 (0 = default {DEFAULT_TOLERANCE_M} m)")
        known = sorted(o.id for o in self.objects)
        if target_id not in known:
            return refused(f"unknown target id {target_id}; known ids {known}")
        try:
            self._ensure_twin(target_id)
        except TwinError as error:
            return refused(str(error))
        twin = self.twin
        if target_id not in twin:
            reason = twin.skipped.get(target_id, "not in the twin")
            return Outcome(False, f"target {target_id} cannot be simulated: {reason}", skipped=dict(twin.skipped))
        poses = {o.id: o.T_world_object for o in self.objects}
        geometry = twin.target_geometry(target_id, poses, with_halfspaces=self.config.uses_hand_geometry)
        start = geometry.com_world if start_com_world is None else np.asarray(start_com_world, dtype=np.float64)
        goal = start + self.goal_displacement(task, displacement)
        for what, point in (("target", geometry.com_world), ("goal", goal)):
            problem = self._reach_problem(point)
            if problem:
                return Outcome(False, f"{what} out of reach: {problem}", skipped=dict(twin.skipped), infeasible=True)
        plan_request = PlanRequest(
            task,
            twin.body_name(target_id),
            displacement,
            tolerance_m or DEFAULT_TOLERANCE_M,
            start_com_world=start_com_world,
            resume_state=resume_state,
            resume_steps_in_state=resume_steps_in_state,
        )
        try:
            state = twin.initial_state(arm_q, float(gripper_opening_m), poses)
            result = self.planner.plan(
                state,
                plan_request,
                geometry,
                feedback=feedback,
                should_stop=should_stop,
                observe=observe,
                stream=stream,
            )
        except TaskInfeasible as error:
            return Outcome(False, f"infeasible: {error}", skipped=dict(twin.skipped), infeasible=True)
        except (ValueError, FloatingPointError, RuntimeError) as error:
            return Outcome(False, f"planning failed: {error}", skipped=dict(twin.skipped))
        return Outcome(
            success=result.success,
            message=result.message,
            final_error_m=result.final_error_m,
            planned=len(result.times_s) > 0,
            result=result,
            twin_objects=len(twin.objects),
            skipped=dict(twin.skipped),
            start_com_world=start,
        )
