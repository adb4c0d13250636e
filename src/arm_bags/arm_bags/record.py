"""record: subscribe to the camera / joint / ground-truth topics and write them to a rosbag2 bag
(mcap or sqlite3) with the pure-Python rosbags package (ros2 bag is not installable here).

    record [OUTPUT_DIR] --ros-args -p storage:=mcap -p use_sim_time:=true -p max_duration_s:=10

Topics are discovered like `ros2 bag record` does: each requested topic is subscribed (serialized,
no deserialization) once a publisher appears, with the publishers' QoS (best effort if any of them
is, transient local if all of them are), and messages are stamped with the node's clock at receipt
(simulated time with use_sim_time:=true). SIGINT/SIGTERM or max_duration_s close the bag cleanly.
"""

import sys
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.utilities import remove_ros_args

from arm_bags.bags import BagError, BagWriter, QosSpec, message_class
from arm_ros.common import RateLimitedErrors, declare, diagnostics_msg, run_node

DEFAULT_TOPICS = [
    "camera/color/image_raw",
    "camera/depth/image_raw",
    "camera/camera_info",
    "camera/pose",
    "joint_states",
    "sim/ground_truth/labels",
    "sim/ground_truth/objects",
    "sim/ground_truth/poses",
]


def default_output() -> str:
    return time.strftime("bags/arm_%Y%m%d_%H%M%S")


def adapted_qos(publisher_infos, depth: int) -> tuple[QoSProfile, QosSpec]:
    """Subscription QoS compatible with every publisher of a topic (rosbag2's adaptive rule)."""
    reliable = all(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in publisher_infos)
    latched = all(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in publisher_infos)
    profile = QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )
    return profile, QosSpec(reliable=reliable, transient_local=latched, depth=depth)


class BagRecorder(Node):
    def __init__(self, **node_options):
        super().__init__("bag_recorder", **node_options)
        output = declare(self, "output", "", "Bag directory to create; '' = bags/arm_<date>_<time>")
        storage = declare(self, "storage", "mcap", "rosbag2 storage plugin", choices=["mcap", "sqlite3"])
        topics = declare(self, "topics", list(DEFAULT_TOPICS), "Topics to record (relative names are resolved)")
        self.max_duration_s = declare(
            self, "max_duration_s", 0.0, "Stop after this long (node clock), seconds; 0 = until stopped", 0.0, 1e6
        )
        self.max_messages = declare(self, "max_messages", 0, "Stop after this many messages; 0 = no limit", 0, 10**9)
        depth = declare(self, "queue_depth", 10, "Subscription queue depth per topic", 1, 1000)
        discovery_s = declare(self, "discovery_period_s", 0.5, "Topic discovery period, seconds", 0.05, 10.0)
        names = [t for t in topics if t]
        if not names:
            raise ValueError("topics must name at least one topic")
        self.wanted = {self.resolve_topic_name(t): t for t in names}
        self.depth = depth
        try:
            self.writer = BagWriter(output or default_output(), storage)
        except BagError as error:
            raise ValueError(str(error)) from None
        self.errors = RateLimitedErrors(self.get_logger())
        self.subscriptions_by_topic = {}
        self.recorded = 0
        self._started = None
        self._closed = False
        self.pub_diag = self.create_publisher(DiagnosticArray, "diagnostics", 10)
        self.create_timer(discovery_s, self.discover)
        self.create_timer(1.0, self.publish_diagnostics)
        self.discover()
        self.get_logger().info(
            f"recording {len(self.wanted)} topic(s) to {self.writer.path} ({storage}): {sorted(self.wanted)}"
        )

    def discover(self) -> None:
        if self._closed:
            return
        types = dict(self.get_topic_names_and_types())
        for topic in sorted(set(self.wanted) - set(self.subscriptions_by_topic)):
            if topic not in types:
                continue
            infos = self.get_publishers_info_by_topic(topic)
            if not infos:
                continue
            msgtype = types[topic][0]
            try:
                cls = message_class(msgtype)
                profile, spec = adapted_qos(infos, self.depth)
                self.writer.add_topic(topic, msgtype, spec)
            except BagError as error:
                self.errors.error(f"topic {topic}", f"cannot record {topic}: {error}")
                continue
            self.subscriptions_by_topic[topic] = self.create_subscription(
                cls, topic, lambda raw, t=topic: self.on_message(t, raw), profile, raw=True
            )
            self.get_logger().info(f"recording {topic} ({msgtype})")
        self._check_limits()

    def on_message(self, topic: str, raw: bytes) -> None:
        if self._closed:
            return
        now_ns = self.get_clock().now().nanoseconds
        if self._started is None:
            self._started = now_ns
        self.writer.write(topic, now_ns, raw)
        self.recorded += 1
        self._check_limits()

    def _check_limits(self) -> None:
        by_time = (
            self.max_duration_s > 0
            and self._started is not None
            and self.get_clock().now().nanoseconds - self._started >= self.max_duration_s * 1e9
        )
        by_count = self.max_messages > 0 and self.recorded >= self.max_messages
        if (by_time or by_count) and not self._closed:
            self.get_logger().info(f"limit reached after {self.recorded} messages; closing the bag")
            self.close()
            rclpy.try_shutdown(context=self.context)

    def publish_diagnostics(self) -> None:
        values = {"messages_recorded": self.recorded, "topics_recorded": len(self.subscriptions_by_topic)}
        values.update({f"count {t}": n for t, n in self.writer.counts.items()})
        self.pub_diag.publish(diagnostics_msg(self, "record", values))

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self.writer.close()
        counts = ", ".join(f"{t}: {n}" for t, n in sorted(self.writer.counts.items())) or "nothing"
        print(f"[record] wrote {self.writer.path}: {counts}", flush=True)


def main(args=None) -> int:
    argv = remove_ros_args(args=sys.argv if args is None else args)[1:]
    if len(argv) > 1 or (argv and argv[0].startswith("-")):
        print("usage: record [OUTPUT_DIR] [--ros-args -p storage:=mcap|sqlite3 -p topics:=[...] ...]")
        return 2
    overrides = [Parameter("output", value=argv[0])] if argv else []
    return run_node(lambda: BagRecorder(parameter_overrides=overrides), args)


if __name__ == "__main__":
    raise SystemExit(main())
