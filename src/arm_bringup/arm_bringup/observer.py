"""The demo's view of the graph: the latest message of every topic it reports on, and diagnostics."""

import time
from collections import OrderedDict

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseStamped
from sensor_msgs.msg import CameraInfo, Image, JointState

from arm_interfaces.msg import ReconstructedObjectArray, SegmentedFrame
from arm_ros.common import latched_qos, sensor_qos
from arm_ros.conversions.images import depth_to_metres, image_to_numpy
from arm_ros.conversions.stamps import time_ns

SEGMENTED_FRAMES_KEPT = 30


class Observer:
    """Collects the latest message of every topic the demo reports on, and the last
    SEGMENTED_FRAMES_KEPT segmented frames by stamp (to find the one a mesh array was built from)."""

    def __init__(self, node):
        self.node, self.latest, self.counts = node, {}, {}
        self.segmented_frames: OrderedDict[int, SegmentedFrame] = OrderedDict()  # by stamp, ns
        self.diagnostics: dict[str, dict] = {}
        qos = sensor_qos("reliable")
        for topic, kind, profile in [
            ("camera/color/image_raw", Image, qos),
            ("camera/depth/image_raw", Image, qos),
            ("camera/camera_info", CameraInfo, qos),
            ("camera/pose", PoseStamped, qos),
            ("sim/ground_truth/labels", Image, qos),
            ("arm/segmented_frame", SegmentedFrame, 2),
            ("arm/meshes", ReconstructedObjectArray, latched_qos()),
            ("sim/ground_truth/objects", ReconstructedObjectArray, latched_qos()),
            ("joint_states", JointState, 10),
            ("sim/ground_truth/poses", PoseArray, 10),
        ]:
            node.create_subscription(kind, topic, lambda m, t=topic: self._store(t, m), profile)
        node.create_subscription(DiagnosticArray, "diagnostics", self._diag, 50)

    def _store(self, topic, msg):
        self.latest[topic] = msg
        self.counts[topic] = self.counts.get(topic, 0) + 1
        if topic == "arm/segmented_frame":
            self.segmented_frames[time_ns(msg.header.stamp)] = msg
            while len(self.segmented_frames) > SEGMENTED_FRAMES_KEPT:
                self.segmented_frames.popitem(last=False)

    def segmented_frame_for(self, header):
        """The kept segmented frame with header's stamp (the frame a mesh array was built from), or None."""
        return self.segmented_frames.get(time_ns(header.stamp))

    def _diag(self, msg):
        for status in msg.status:
            self.diagnostics[status.name] = {kv.key: kv.value for kv in status.values}

    def wait(self, topics, timeout_s: float, min_count: int = 1) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            rclpy.spin_once(self.node, timeout_sec=0.05)
            if all(self.counts.get(t, 0) >= min_count for t in topics):
                return True
        return False

    def newer(self, topic: str, stamp, timeout_s: float):
        """The first message on topic stamped after `stamp` (a builtin_interfaces Time), or None when
        none came within timeout_s."""
        after_ns = time_ns(stamp)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            rclpy.spin_once(self.node, timeout_sec=0.05)
            msg = self.latest.get(topic)
            if msg is not None and time_ns(msg.header.stamp) > after_ns:
                return msg
        return None

    def frame(self):
        rgb = image_to_numpy(self.latest["camera/color/image_raw"])
        depth = depth_to_metres(self.latest["camera/depth/image_raw"])
        return rgb, depth
