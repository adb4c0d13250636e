"""segmentation_node: synchronizes RGB, depth, camera_info and camera pose (and, with
use_ground_truth_masks, the simulator's label image), segments the latest complete frame and
publishes arm_interfaces/SegmentedFrame plus a colourised overlay for viewers.

With camera_pose_source:=estimate there is no camera/pose input: T_world_camera is estimated from
each frame's depth (arm_segmentation.pose_tracking: the last estimate is reused while its table
plane still fits), published on camera/pose/estimated and on /tf as the frame 'table' under the
depth image's optical frame, and a frame without a usable support plane is skipped with the reason
in the log and in /diagnostics. With camera_pose_source:=tf, T_world_camera is looked up on /tf and
/tf_static from world_frame to the depth image's frame_id (the driver's optical frame); a frame
without that transform is skipped, and says which frames /tf knows.

While the planner serves a goal (pause_during_goals, as reconstruction_node) camera messages are
dropped unprocessed: reconstruction holds frames back then anyway, and planning gets the CPU.
Set it false on both nodes for closed-loop re-planning from new meshes (plan_node's replan_period_s)."""

import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import CameraInfo, Image, JointState, PointCloud2

from arm_interfaces.msg import SegmentedFrame
from arm_ros.common import (
    RateLimitedErrors,
    declare_settings,
    diagnostics_msg,
    lower_cpu_priority,
    run_node,
    sensor_qos,
)
from arm_ros.conversions.poses import matrix_to_pose, matrix_to_transform_msg
from arm_ros.conversions.stamps import cdr_header_stamp_ns, time_ns
from arm_ros.goal_activity import goal_pause
from arm_ros.tf import TfPublisher, tf_listener
from arm_segmentation.boundary_net import shared_predictor
from arm_segmentation.camera_pose_estimate import CameraPoseError
from arm_segmentation.frame_processing import FrameError, decode_camera_frame, object_cloud, segment_frame
from arm_segmentation.merge_model import shared_classifier
from arm_segmentation.node_config import SegmentationNodeConfig
from arm_segmentation.outline_model import shared_outline_classifier
from arm_segmentation.pose_tracking import CameraPoseTracker
from arm_segmentation.self_filter import SelfFilterParams, arm_positions, base_pose, self_mask
from arm_segmentation.synchronizer import ApproximateTimeSynchronizer

TOPICS = {
    "rgb": (Image, "camera/color/image_raw"),
    "depth": (Image, "camera/depth/image_raw"),
    "camera_info": (CameraInfo, "camera/camera_info"),
    "pose": (PoseStamped, "camera/pose"),
    "labels": (Image, "sim/ground_truth/labels"),
}
# Messages each input's reader keeps (see __init__).
INPUT_HISTORY = 3
ESTIMATED_WORLD_FRAME = "table"  # the estimate's frame: z up, table top z = 0, origin under the camera


def stamp_s(msg) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


class SegmentationNode(Node):
    def __init__(self):
        super().__init__("segmentation_node")
        self.config = config = declare_settings(self, SegmentationNodeConfig())
        self.use_ground_truth = config.use_ground_truth_masks
        self.cpu_niceness = lower_cpu_priority(config.cpu_niceness)
        self.world_frame, self.camera_frame = config.world_frame, config.camera_frame
        self.params = params = config.segmentation
        try:  # loaded now: a bad checkpoint fails at start with one clear line, not per frame
            predictor = shared_predictor(params.boundary)
        except (FileNotFoundError, ValueError) as error:
            raise ValueError(f"boundary network: {error}") from error
        if predictor is not None:
            # One thread: on a loaded machine a niced process's extra OpenMP threads wait on each other
            # (a 2-thread network took the frame from about 0.12 s to 0.7 s in the running graph).
            import torch

            torch.set_num_threads(1)
        self.get_logger().info(
            f"boundary network: {predictor.path}" if predictor else "boundary network off: geometric and colour cues"
        )
        self._load_classifier(shared_classifier, params.merge, "merge", "merging by colour", predictor)
        self._load_classifier(shared_outline_classifier, params.outline, "outline", "outlines by colour", predictor)
        pose_source, slop_s = config.camera_pose_source, config.sync_tolerance_s
        self.tracker = CameraPoseTracker() if pose_source == "estimate" else None
        self.tf_listener = tf_listener(self) if pose_source == "tf" else None
        self.tf = TfPublisher(self)
        self.inputs = ["rgb", "depth", "camera_info"] + (["pose"] if pose_source == "topic" else [])
        self.inputs += ["labels"] if self.use_ground_truth else []
        self.sync = ApproximateTimeSynchronizer(len(self.inputs), slop_s, config.sync_queue_size)
        self.errors = RateLimitedErrors(self.get_logger())
        self._start_self_filter(config)
        # Each input is taken as serialized bytes (its stamp read from them) and only the set the
        # synchronizer matches is deserialized; each reader keeps the newest INPUT_HISTORY messages, so
        # that the set of one camera frame is still there when a frame has been segmented, whatever
        # order and spread its messages arrived in.
        qos = sensor_qos(config.image_reliability, depth=INPUT_HISTORY)
        for index, name in enumerate(self.inputs):
            msg_type, topic = TOPICS[name]
            self.create_subscription(msg_type, topic, lambda raw, i=index: self.on_message(i, raw), qos, raw=True)
        self.pub_estimated_pose = self.create_publisher(PoseStamped, "camera/pose/estimated", 10)
        # Reliable, but only the newest frames are kept for a reader that has not acknowledged them: each
        # is about 2.8 MB (640x480), and a history of 10 grew the node by about 25 MB when the
        # reconstruction node fell behind. Its reader keeps one frame and reconstructs the newest.
        self.pub_frame = self.create_publisher(SegmentedFrame, "arm/segmented_frame", sensor_qos("reliable", depth=2))
        self.pub_overlay = self.create_publisher(Image, "arm/segmentation/overlay", qos)
        self.pub_cloud = self.create_publisher(PointCloud2, "arm/segmentation/points", qos)
        self.pub_diag = self.create_publisher(DiagnosticArray, "diagnostics", 10)
        self.frames_published = 0
        self.frames_rejected = 0
        self.last_latency_ms = 0.0
        self.last_instances = 0
        self.last_empty_reason = ""
        self.last_error = ""
        self.messages_skipped_for_goals = 0
        self.goals = goal_pause(self, config.goal_pause)
        self.create_timer(1.0, self.publish_diagnostics)
        mode = "ground-truth masks" if self.use_ground_truth else "segmentation"
        self.get_logger().info(
            f"segmentation_node ready ({mode}, camera pose from {pose_source}, sync tolerance {slop_s * 1e3:.0f} ms)"
        )

    def _load_classifier(self, shared, params, name: str, fallback: str, predictor) -> None:
        """Load a learned classifier now, so bad weights fail at start with one clear line, not per
        frame; warn when it will not run for want of the boundary network's maps."""
        try:
            classifier = shared(params)
        except (FileNotFoundError, ValueError) as error:
            raise ValueError(f"{name} classifier: {error}") from error
        if classifier is not None and predictor is None:
            self.get_logger().warning(f"{name} classifier needs the boundary network's maps: {fallback}")

    def _start_self_filter(self, config: SegmentationNodeConfig) -> None:
        self.self_filter = config.self_filter
        self.T_world_base = base_pose([float(v) for v in config.robot_base_xyz_m], config.robot_base_yaw_rad)
        self.self_filter_params = SelfFilterParams(padding_m=config.self_filter_padding_m)
        self.joint_q = None
        if self.self_filter:
            self.create_subscription(JointState, "joint_states", self.on_joint_state, 10)

    def on_joint_state(self, msg: JointState) -> None:
        try:
            self.joint_q = arm_positions(msg.name, msg.position)
        except ValueError as error:
            self.errors.error("bad_joint_state", f"joint_states ignored: {error}")

    def arm_mask(self, frame):
        if self.joint_q is None:
            return None
        return self_mask(
            self.joint_q, self.T_world_base, frame.K, frame.T_world_camera, frame.depth_m.shape, frame.depth_m,
            self.self_filter_params,
        )  # fmt: skip

    def on_message(self, index: int, raw: bytes) -> None:
        """One serialized input message: matched by its header stamp, deserialized with its set."""
        if self.goals is not None and self.goals.seconds_left() > 0:
            self.messages_skipped_for_goals += 1
            return
        stamp_ns = cdr_header_stamp_ns(raw)
        item = raw
        if stamp_ns is None:  # not plain CDR: the message itself gives its stamp
            item = self.deserialize(index, raw)
            if item is None:
                return
            stamp_ns = time_ns(item.header.stamp)
        stamp = 1e-9 * stamp_ns
        if not abs(stamp) < 1e12:
            self.errors.error("bad_stamp", f"{self.inputs[index]} message has an invalid stamp")
            return
        match = self.sync.add(index, stamp, item)
        if match is None:
            return
        messages = [self.deserialize(i, m) if isinstance(m, bytes) else m for i, m in enumerate(match[1])]
        if all(m is not None for m in messages):
            self.process(**dict(zip(self.inputs, messages, strict=True)))

    def deserialize(self, index: int, raw: bytes):
        """The input's message from its serialized bytes, or None (logged) when they do not decode."""
        msg_type, topic = TOPICS[self.inputs[index]]
        try:
            return deserialize_message(raw, msg_type)
        except Exception as error:  # whatever the bytes, the node goes on
            self.errors.error("undecodable", f"{topic}: a message that does not decode as {msg_type.__name__}: {error}")
            return None

    def estimated_pose(self, frame, depth) -> PoseStamped:
        """Estimate (or reuse) T_world_camera for a decoded frame, publish it and fill the frame in."""
        try:
            estimate = self.tracker.update(frame.depth_m, frame.K)
        except CameraPoseError as error:
            raise FrameError(f"camera pose: {error}") from error
        frame.T_world_camera, frame.world_frame_id = estimate.T_world_camera, ESTIMATED_WORLD_FRAME
        pose = PoseStamped(pose=matrix_to_pose(estimate.T_world_camera))
        pose.header.stamp, pose.header.frame_id = depth.header.stamp, ESTIMATED_WORLD_FRAME
        self.pub_estimated_pose.publish(pose)
        camera = self.camera_frame or depth.header.frame_id
        if camera:  # the table under the camera's optical frame, which has its own parent
            T_camera_table = np.linalg.inv(estimate.T_world_camera)
            self.tf.send([matrix_to_transform_msg(T_camera_table, camera, ESTIMATED_WORLD_FRAME, depth.header.stamp)])
        return pose

    def tf_pose(self, frame, depth) -> PoseStamped:
        """T_world_camera from /tf for a decoded frame (world_frame <- camera_frame, or the depth image's
        frame_id)."""
        camera = self.camera_frame or depth.header.frame_id
        T = self.tf_listener.lookup(self.world_frame, camera) if camera else None
        if T is None:
            known = ", ".join(sorted(self.tf_listener.frames())) or "none"
            raise FrameError(
                f"camera pose: no transform from '{camera}' to '{self.world_frame}' on /tf (frames: {known})"
            )
        frame.T_world_camera, frame.world_frame_id = T, self.world_frame
        pose = PoseStamped(pose=matrix_to_pose(T))
        pose.header.stamp, pose.header.frame_id = depth.header.stamp, self.world_frame
        return pose

    def process(self, rgb, depth, camera_info, pose=None, labels=None) -> None:
        start = time.perf_counter()
        try:
            decoded = decode_camera_frame(rgb, depth, camera_info, pose)
            if self.tracker is not None:
                pose = self.estimated_pose(decoded, depth)
            elif self.tf_listener is not None:
                pose = self.tf_pose(decoded, depth)
            # the robot base pose is given in the world frame of camera/pose, not an estimated one
            exclude_fn = self.arm_mask if self.self_filter and self.tracker is None else None
            frame, overlay = segment_frame(decoded, depth, camera_info, pose, labels, self.params, exclude_fn)
        except FrameError as error:
            self.frames_rejected += 1
            self.last_error = str(error)
            cause = f"{type(error).__name__}: {error}"
            self.errors.error(cause, f"frame at t={stamp_s(depth):.3f} s rejected: {error}")
            return
        self.pub_frame.publish(frame)
        self.pub_overlay.publish(overlay)
        if self.pub_cloud.get_subscription_count() > 0:  # built only for a listener (RViz, MoveIt's octomap)
            self.pub_cloud.publish(object_cloud(decoded, depth.header))
        self.frames_published += 1
        self.last_latency_ms = 1e3 * (time.perf_counter() - start)
        self.last_instances = len(frame.instance_ids)
        self.last_empty_reason = frame.empty_reason
        if frame.empty_reason:
            self.get_logger().warning(f"no instance: {frame.empty_reason}", throttle_duration_sec=5.0)

    def publish_diagnostics(self) -> None:
        level = DiagnosticStatus.OK
        message = "ok"
        if self.frames_rejected and self.last_error:
            level, message = DiagnosticStatus.WARN, f"last rejected frame: {self.last_error}"
        elif self.last_empty_reason:
            level, message = DiagnosticStatus.WARN, f"last frame had no instance: {self.last_empty_reason}"
        values = {
            "frames_published": self.frames_published,
            "frames_rejected": self.frames_rejected,
            "messages_received": self.sync.stats.received,
            "stale_messages_dropped": self.sync.stats.dropped_stale,
            "last_latency_ms": self.last_latency_ms,
            "last_instances": self.last_instances,
            "last_empty_reason": self.last_empty_reason,
            "ground_truth_masks": self.use_ground_truth,
            "self_filter": self.self_filter,
            "joint_states_received": self.joint_q is not None,
            "goal_pauses": self.goals.pauses if self.goals else 0,
            "paused_for_goal": bool(self.goals and self.goals.seconds_left() > 0),
            "messages_skipped_for_goals": self.messages_skipped_for_goals,
        }
        array = diagnostics_msg(self, "segmentation", values, level, message)
        if self.tracker is not None:
            array.status.append(self.pose_status())
        self.pub_diag.publish(array)

    def pose_status(self) -> DiagnosticStatus:
        """ERROR with the reason while the last frame had no usable support plane, WARN when the plane
        holds under a fifth of the valid depth pixels, else OK."""
        stats, last = self.tracker.stats, self.tracker.last
        inliers = last.inlier_fraction if last is not None else 0.0
        if stats.last_error:
            level, message = DiagnosticStatus.ERROR, f"no camera pose: {stats.last_error}"
        elif last is None:
            level, message = DiagnosticStatus.WARN, "no frame yet"
        elif inliers < 0.2:
            level, message = DiagnosticStatus.WARN, f"table plane holds only {inliers:.0%} of the depth pixels"
        else:
            level, message = DiagnosticStatus.OK, "ok"
        values = {
            "inlier_fraction": inliers,
            "camera_height_m": float(last.T_world_camera[2, 3]) if last is not None else 0.0,
            "estimates": stats.estimates,
            "reused": stats.reuses,
            "failures": stats.failures,
            "last_error": stats.last_error,
        }
        return diagnostics_msg(self, "camera_pose_estimate", values, level, message).status[0]


def main(args=None) -> int:
    return run_node(SegmentationNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
