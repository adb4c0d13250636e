"""sim_node: owns the ground-truth MuJoCo world, publishes RGB-D + camera + joint states + ground
truth and /clock (simulated time), and executes the robot's commands as ros2_control does: the arm's
FollowJointTrajectory and the gripper's GripperCommand actions (arm_sim.controllers), or a
JointTrajectory on /arm/joint_trajectory."""

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseStamped
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory

from arm_interfaces.msg import ReconstructedObjectArray
from arm_ros.common import (
    RateLimitedErrors,
    declare_settings,
    diagnostics_msg,
    latched_qos,
    run_node,
    sensor_qos,
)
from arm_ros.conversions.images import camera_info_from_K, numpy_to_image
from arm_ros.conversions.meshes import reconstructed_object_msg
from arm_ros.conversions.poses import matrix_to_pose
from arm_ros.goal_activity import goal_pause
from arm_sim import robot
from arm_sim.controllers import SimControllers, trajectory_start_s
from arm_sim.core import SimSession
from arm_sim.node_config import SimNodeConfig


class SimNode(Node):
    def __init__(self):
        super().__init__("sim_node")
        self.config = config = declare_settings(self, SimNodeConfig())
        eye, target = config.camera_eye, config.camera_target
        if not np.all(np.isfinite(eye + target)):
            raise ValueError("camera_eye and camera_target must be 3 finite numbers each")
        self.camera_rate_hz, self.physics_rate_hz = config.camera_rate_hz, config.physics_rate_hz
        self.depth_noise = config.depth_noise
        self.world_frame, self.camera_frame = config.world_frame_id, config.camera_frame_id
        self.session = SimSession(
            seed=config.seed,
            objects=config.objects or None,
            split=config.split,
            n_objects=config.n_objects or None,
            camera_eye=eye,
            camera_target=target,
            width=config.width,
            height=config.height,
            fovy_deg=config.fovy_deg,
            depth_noise=config.depth_noise,
            visual_domain=config.visual_domain,
        )
        self.errors = RateLimitedErrors(self.get_logger())
        qos = sensor_qos(config.image_reliability)
        self.pub_rgb = self.create_publisher(Image, "camera/color/image_raw", qos)
        self.pub_depth = self.create_publisher(Image, "camera/depth/image_raw", qos)
        self.pub_info = self.create_publisher(CameraInfo, "camera/camera_info", qos)
        self.pub_pose = self.create_publisher(PoseStamped, "camera/pose", qos)
        self.pub_labels = self.create_publisher(Image, "sim/ground_truth/labels", qos)
        self.pub_joints = self.create_publisher(JointState, "joint_states", 10)
        self.pub_clock = self.create_publisher(ClockMsg, "clock", 10)
        self.pub_truth_poses = self.create_publisher(PoseArray, "sim/ground_truth/poses", 10)
        self.pub_truth = self.create_publisher(ReconstructedObjectArray, "sim/ground_truth/objects", latched_qos())
        self.pub_diag = self.create_publisher(DiagnosticArray, "diagnostics", 10)
        self.create_subscription(JointTrajectory, "arm/joint_trajectory", self.on_trajectory, 10)
        self.controllers = SimControllers(
            self,
            self.session,
            config.arm_controller,
            config.gripper_controller,
            lambda: self.session.time_s,
            self.header,
        )
        self._next_render_s = 0.0
        self._render_ms = 0.0
        self.frames_published = 0
        self.trajectories_followed = self.trajectories_rejected = 0
        self.goals = goal_pause(self, config.goal_pause)
        # the sim is the clock source: it ticks on the steady clock, also when run with use_sim_time:=true
        self.create_timer(1.0 / self.physics_rate_hz, self.on_tick, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.publish_ground_truth()
        self.get_logger().info(
            f"sim ready: {len(self.session.scene.objects)} objects (seed {config.seed}), "
            f"camera {self.camera_rate_hz} Hz"
        )

    def stamp(self) -> Time:
        nanoseconds = int(round(self.session.time_s * 1e9))
        return Time(sec=nanoseconds // 10**9, nanosec=nanoseconds % 10**9)

    def header(self, frame_id: str) -> Header:
        return Header(stamp=self.stamp(), frame_id=frame_id)

    def on_trajectory(self, msg: JointTrajectory) -> None:
        try:
            times = [p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in msg.points]
            positions = [list(p.positions) for p in msg.points]
            targets = self.session.follow(msg.joint_names, times, positions, self.trajectory_start_s(msg))
            self.controllers.cancel_arm("replaced by a trajectory on arm/joint_trajectory")
            self.trajectories_followed += 1
            self.get_logger().info(f"executing trajectory: {len(msg.points)} points, {targets} servo targets")
        except ValueError as error:
            self.trajectories_rejected += 1
            self.errors.error("bad_trajectory", f"rejected trajectory: {error}")

    def trajectory_start_s(self, msg: JointTrajectory) -> float | None:
        """The trajectory's time zero on the sim clock (s); None: start now (controllers.trajectory_start_s)."""
        start_s, warning = trajectory_start_s(msg.header.stamp, self.session.time_s)
        if warning:
            self.errors.error("trajectory_stamp", warning)
        return start_s

    def on_tick(self) -> None:
        self.session.step(1.0 / self.physics_rate_hz)
        self.controllers.tick()
        self.pub_clock.publish(ClockMsg(clock=self.stamp()))
        self.publish_joint_state()
        due = self.session.time_s + 1e-9 >= self._next_render_s
        if due and (self.goals is None or self.goals.seconds_left() == 0):  # no frames during goals
            self._next_render_s = self.session.time_s + 1.0 / self.camera_rate_hz
            self.publish_frame()

    def publish_joint_state(self) -> None:
        q, qd = self.session.world.joint_positions(), self.session.world.joint_velocities()
        names = list(robot.JOINT_NAMES) + [robot.FINGER_JOINT_NAMES[0]]
        self.pub_joints.publish(
            JointState(header=self.header(""), name=names, position=q.tolist(), velocity=qd.tolist())
        )

    def publish_frame(self) -> None:
        frame, render_ms = self.session.render()
        self._render_ms = render_ms
        header = self.header(self.camera_frame)
        h, w = frame.depth_m.shape
        self.pub_rgb.publish(numpy_to_image(frame.rgb, "rgb8", header))
        self.pub_depth.publish(numpy_to_image(frame.depth_m, "32FC1", header))
        self.pub_info.publish(camera_info_from_K(frame.K, w, h, header))
        pose = matrix_to_pose(frame.T_world_camera)
        self.pub_pose.publish(PoseStamped(header=self.header(self.world_frame), pose=pose))
        self.pub_labels.publish(numpy_to_image(frame.labels, "16UC1", header))
        poses = [matrix_to_pose(T) for T in self.session.world.object_poses()]
        self.pub_truth_poses.publish(PoseArray(header=self.header(self.world_frame), poses=poses))
        self.frames_published += 1
        self.pub_diag.publish(
            diagnostics_msg(
                self,
                "render",
                {
                    "render_ms": render_ms,
                    "frames_published": self.frames_published,
                    "sim_time_s": self.session.time_s,
                    "trajectories_followed": self.trajectories_followed,
                    "trajectories_rejected": self.trajectories_rejected,
                    "arm_goals": self.controllers.goals["arm"],
                    "gripper_goals": self.controllers.goals["gripper"],
                    "goal_pauses": self.goals.pauses if self.goals is not None else 0,
                },
            )
        )

    def publish_ground_truth(self) -> None:
        msg = ReconstructedObjectArray(header=self.header(self.world_frame))
        msg.table_height_m = float(self.session.scene.table_height_m)
        fractions = self.session.visible_fractions()
        for i, (mesh, parts) in enumerate(self.session.ground_truth_meshes()):
            msg.objects.append(reconstructed_object_msg(i + 1, mesh, parts, fractions[i], "ground_truth"))
        self.pub_truth.publish(msg)

    def close(self) -> None:
        self.controllers.close()
        self.session.close()


def main(args=None):
    raise SystemExit(run_node(SimNode, args))


if __name__ == "__main__":
    main()
