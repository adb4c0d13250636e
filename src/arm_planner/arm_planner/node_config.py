"""plan_node's settings: the planner's (PlannerConfig) and how its plans reach the robot.

The node declares the settings marked as parameters (arm_core.settings); config/plan_node.yaml is
rendered from this dataclass."""

from __future__ import annotations

from dataclasses import dataclass, field

from arm_core.settings import setting
from arm_planner.planner import PlannerConfig

# plan_only: plan and return the trajectory in the result. execute: plan to the end, then send the
# plan if it met the task in the twin (else hold it back and say so). stream: send the plan in parts
# while planning the rest (receding horizon). replan: execute replan_period_s of the plan, then
# re-plan from the newest joint states and meshes (closed loop).
EXECUTION_MODES = ("plan_only", "execute", "stream", "replan")


@dataclass
class PlanNodeConfig:
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    execution: str = setting(
        "stream",
        "plan_only: return the plan; execute: send a finished plan that met the task in the twin; stream: "
        "send the plan in parts while planning the rest; replan: re-plan every replan_period_s (closed loop)",
        choices=EXECUTION_MODES,
        parameter=True,
    )
    controller_interface: str = setting(
        "ros2_control",
        "ros2_control: FollowJointTrajectory and GripperCommand goals; topic: JointTrajectory on "
        "arm/joint_trajectory (no execution feedback)",
        choices=("ros2_control", "topic"),
        parameter=True,
    )
    arm_controller: str = setting(
        "arm_controller", "Joint trajectory controller: <name>/follow_joint_trajectory", parameter=True
    )
    gripper_controller: str = setting(
        "gripper_controller", "Gripper action controller: <name>/gripper_cmd", parameter=True
    )
    gripper_max_effort_n: float = setting(
        70.0, "GripperCommand max_effort, N (0: the controller's)", 0.0, 1000.0, parameter=True
    )
    robot_base_xyz_m: list = setting(
        [-0.55, 0.0, 0.0],
        "World position of the robot base (as segmentation_node's); the twin stands it on the table at x, y",
        parameter=True,
    )
    observe_timeout_s: float = setting(
        15.0,
        "After the motion, wait this long for meshes of a newer frame to observe the target (0: do not), s",
        0.0,
        600.0,
        parameter=True,
    )
    replan_period_s: float = setting(
        0.5,
        "replan: motion executed between re-plans, s (new meshes need pause_during_goals false upstream)",
        0.02,
        60.0,
        parameter=True,
    )
    joint_state_timeout_s: float = setting(
        2.0, "Refuse goals when joint states are older than this, s (0: never)", 0.0, 3600.0, parameter=True
    )
    execution_margin_s: float = setting(
        5.0, "Wait this long past the trajectory's end for the arm controller's result, s", 0.0, 600.0
    )
    stream_lead_s: float = setting(0.5, "stream: motion planned before the first part is sent, s", 0.0, 60.0)
    stream_period_s: float = setting(0.2, "stream: motion planned per further part, s", 0.0, 60.0)
    max_replans: int = setting(10, "replan: re-plans per goal at most", 0, 1000)
    replan_target_radius_m: float = setting(
        0.15, "replan: the target in newer meshes is the object nearest its last centre, within this, m", 0.0, 10.0
    )
    feedback_every_steps: int = setting(10, "Publish action feedback every this many MPPI steps", 1, 1000)
    max_object_size_m: float = setting(1.0, "Leave objects larger than this out of the twin, m", 0.01, 100.0)
    scene_history: int = setting(20, "/arm/meshes arrays kept for goals naming one by stamp", 1, 1000)
    twin_timestep_s: float = setting(0.01, "Twin physics step, s (divides control_dt_s)", 0.001, 0.02)
