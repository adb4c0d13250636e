"""reconstruction_node: /arm/segmented_frame -> /arm/meshes (reliable, transient-local) + RViz markers.

Frames are reconstructed by one worker thread that always takes the newest frame; a frame that
arrives while another waits replaces it (counted as dropped). While the planner serves a goal
(pause_during_goals) frames wait, so planning has the CPU, and a frame in progress when the goal
comes is abandoned at the next stage boundary; the newest is reconstructed after.
Malformed frames are logged (rate-limited) and nothing is published for them. Diagnostics
(per-stage latency, frame counts) follow every frame and a 1 s timer.
"""

import threading
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy._rclpy_pybind11 import RCLError
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import MarkerArray

from arm_core.frames import FrameInputError
from arm_interfaces.msg import ReconstructedObjectArray, SegmentedFrame
from arm_ros.common import (
    RateLimitedErrors,
    declare_settings,
    diagnostics_msg,
    latched_qos,
    lower_cpu_priority,
    run_node,
    sensor_qos,
)
from arm_ros.conversions import ConversionError
from arm_ros.conversions.frames import frame_from_msg
from arm_ros.goal_activity import goal_pause
from arm_ros.tf import TfPublisher

from .checkpoint import CheckpointError
from .messages import main_table_height, markers_msg, object_transforms, objects_to_msg
from .node_config import ReconstructionNodeConfig
from .pipeline import STAGES, ReconstructionPreempted, Reconstructor


class ReconstructionNode(Node):
    def __init__(self, **node_options):
        super().__init__("reconstruction_node", **node_options)
        self.config = config = declare_settings(self, ReconstructionNodeConfig())
        settings = config.reconstruction
        self.marker_alpha = config.marker_alpha
        self.min_period_s = 1.0 / config.max_rate_hz if config.max_rate_hz > 0 else 0.0
        self.cpu_niceness = lower_cpu_priority(config.cpu_niceness)
        try:
            self.reconstructor = Reconstructor(settings)
        except CheckpointError as error:
            raise ValueError(f"checkpoint: {error}") from None

        self.errors = RateLimitedErrors(self.get_logger())
        self.pub_objects = self.create_publisher(ReconstructedObjectArray, "arm/meshes", latched_qos())
        self.pub_markers = self.create_publisher(MarkerArray, "arm/meshes/markers", latched_qos())
        self.pub_diag = self.create_publisher(DiagnosticArray, "diagnostics", 10)
        self.tf = TfPublisher(self)  # each object's frame object_<id>, for RViz and TF users
        self.create_subscription(
            SegmentedFrame, "arm/segmented_frame", self.on_frame, sensor_qos(config.frame_reliability, 1)
        )

        self.received = self.processed = self.dropped = self.rejected = 0
        self.last_start_s = -float("inf")  # time.monotonic() when the last frame's reconstruction began
        self._latest: SegmentedFrame | None = None
        self._wake = threading.Condition()
        self._stop = False
        self._stage_values: dict = {}
        self._status = (DiagnosticStatus.OK, "waiting for frames")
        self.create_timer(1.0, self.publish_diagnostics)
        self.goals = goal_pause(self, config.goal_pause, self._notify)
        self.preempted = 0
        if self.goals is not None:  # a frame in progress when a goal comes is abandoned, redone after it
            self.reconstructor.should_stop = lambda: self.goals.seconds_left() > 0
        self._worker = threading.Thread(target=self._work, name="reconstruction", daemon=True)
        self._worker.start()
        self.get_logger().info(
            f"reconstruction ready: method {settings.method}, resolution {self.reconstructor.resolution}, "
            f"device {self.reconstructor.device}"
        )

    def on_frame(self, msg: SegmentedFrame) -> None:
        with self._wake:
            self.received += 1
            if self._latest is not None:
                self.dropped += 1
            self._latest = msg
            self._wake.notify()

    def _notify(self) -> None:
        with self._wake:
            self._wake.notify()

    def _wait_s(self) -> float:
        """Seconds until the next frame may start (<= 0: now): max_rate_hz's spacing, and a goal being
        served (checked again at least once a second, so a planner that died is noticed)."""
        wait_s = self.last_start_s + self.min_period_s - time.monotonic()
        if self.goals is not None and (goal_s := self.goals.seconds_left()) > 0:
            wait_s = max(wait_s, min(goal_s, 1.0))
        return wait_s

    def _work(self) -> None:
        while True:
            with self._wake:
                while not self._stop and (self._latest is None or self._wait_s() > 0):
                    self._wake.wait(None if self._latest is None else self._wait_s())
                if self._stop:
                    return
                msg, self._latest = self._latest, None  # the newest frame: older ones were dropped
            self.last_start_s = time.monotonic()
            self.process(msg)

    def _publish(self, publisher, msg) -> bool:
        """Publish unless shutting down; a publish that SIGINT/SIGTERM invalidated is dropped quietly."""
        if self._stop or not self.context.ok():
            return False
        try:
            publisher.publish(msg)
        except Exception:
            if self.context.ok() and not self._stop:
                raise
            return False
        return True

    def process(self, msg: SegmentedFrame) -> None:
        started = time.perf_counter()
        try:
            frame = frame_from_msg(msg)
            objects = self.reconstructor(frame.rgb, frame.depth_m, frame.K, frame.T_world_camera, frame.labels)
        except ReconstructionPreempted:
            self.preempted += 1
            with self._wake:
                if self._latest is None:  # nothing newer came: this frame is redone after the goal
                    self._latest = msg
            return
        except (ConversionError, FrameInputError) as error:
            self._reject(f"{type(error).__name__}: {error}", f"dropping malformed segmented frame: {error}")
            return
        except Exception as error:  # a failure inside one frame must not kill the node
            self._reject("reconstruction", f"reconstruction failed: {type(error).__name__}: {error}")
            return
        header = msg.header
        header.frame_id = frame.world_frame_id or "world"
        table_height_m = main_table_height(objects, self.reconstructor.settings.table_height_m or 0.0)
        if not self._publish(self.pub_objects, objects_to_msg(objects, header, table_height_m)):
            return
        self._publish(self.pub_markers, markers_msg(objects, header, self.marker_alpha))
        transforms = object_transforms(objects, header)
        if transforms:
            self._publish(self.tf.dynamic, TFMessage(transforms=transforms))
        failed = [o for o in objects if not o.ok]
        for obj in failed:
            self.errors.error(f"object {obj.id}", f"object {obj.id} not reconstructed: {obj.error}")
        for obj in objects:
            if obj.from_observed_voxels:
                self.errors.error(
                    f"observed {obj.id}", f"object {obj.id}: the network predicted nothing; meshed its observed voxels"
                )
        values = {f"{stage}_ms": 1000.0 * self.reconstructor.last_timings_s[stage] for stage in STAGES}
        values.update(
            frame_to_meshes_ms=1000.0 * (time.perf_counter() - started),
            objects=len(objects) - len(failed),
            failed_objects=len(failed),
        )
        level = DiagnosticStatus.WARN if failed else DiagnosticStatus.OK
        self.processed += 1  # after the timings above, so a status counting this frame carries them
        self._update_diagnostics(values, level, f"{len(failed)} object(s) not reconstructed" if failed else "ok")

    def _reject(self, cause: str, message: str) -> None:
        self.rejected += 1
        self.errors.error(cause, message)
        self._update_diagnostics({}, DiagnosticStatus.WARN, message[:200])

    def _update_diagnostics(self, values: dict, level, message: str) -> None:
        self._stage_values.update(values)
        self._status = (level, message)
        self.publish_diagnostics()

    def publish_diagnostics(self) -> None:
        """Per-stage latency of the last frame and the frame counts (also on a 1 s timer)."""
        values = {
            **self._stage_values,
            "frames_received": self.received,
            "frames_processed": self.processed,
            "frames_dropped": self.dropped,
            "frames_rejected": self.rejected,
            "goal_pauses": self.goals.pauses if self.goals else 0,
            "frames_preempted_by_goals": self.preempted,
            "paused_for_goal": bool(self.goals and self.goals.seconds_left() > 0),
        }
        level, message = self._status
        self._publish(self.pub_diag, diagnostics_msg(self, "reconstruction", values, level, message))

    def close(self) -> None:
        """Stop the worker. A frame still being reconstructed after 5 s is abandoned: its publishes
        are dropped (see _publish), so a node stopped mid-frame on a loaded CPU still exits well
        inside the usual 15 s SIGINT-to-SIGKILL grace."""
        with self._wake:
            self._stop = True
            self._wake.notify()
        self._worker.join(timeout=5.0)


def _make_node() -> ReconstructionNode:
    try:
        return ReconstructionNode()
    except RCLError:
        if not rclpy.ok():  # SIGINT/SIGTERM arrived while the node was starting
            raise ExternalShutdownException() from None
        raise


def main(args=None) -> int:
    return run_node(_make_node, args)


if __name__ == "__main__":
    raise SystemExit(main())
