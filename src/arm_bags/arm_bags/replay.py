"""replay: publish a rosbag2 bag's messages into the graph, with the bag's timing or as fast as the
pipeline consumes them, and publish /clock (bag time) for nodes run with use_sim_time:=true.

    replay BAG_DIR --ros-args -p mode:=original -p rate:=1.0 -p loop:=false
    replay BAG_DIR --ros-args -p mode:=consumed -p consumed_topic:=arm/meshes

mode original: message i is published at start + (t_i - t_0) / rate (t = the bag's receive stamps).
mode consumed: camera frames (messages of frame_topics sharing a header stamp) are published one
after the other; the next frame waits until consumed_topic has published a message stamped at or
after the previous frame (or consumed_timeout_s passed). Every frame is then processed once. Until
a first frame has been consumed, the pending frame is sent again every first_frame_retry_s: a link
inside the pipeline can match after the frame was sent.
start_offset_s / duration_s replay a window of the bag (bag time). In mode consumed the replay
first waits for a subscriber on every replayed topic and a publisher on consumed_topic (the end of
the chain is up). With loop:=true the bag repeats; header stamps (and /clock) are shifted by one
bag period per pass so they keep increasing. Messages that do not decode are skipped with a rate-limited error; an
unreadable bag is a configuration error (exit code 2).
"""

import sys
import threading
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.utilities import remove_ros_args
from rosgraph_msgs.msg import Clock

from arm_bags.bags import (
    BagError,
    BagReader,
    FrameGroups,
    LoopStamps,
    header_stamp_ns,
    message_class,
    shift_stamps,
)
from arm_ros.common import (
    RateLimitedErrors,
    declare,
    diagnostics_msg,
    exit_refused,
    spin_until_shutdown,
    use_large_socket_buffers,
)
from arm_ros.conversions.stamps import ns_to_time

FRAME_TOPICS = [
    "camera/color/image_raw",
    "camera/depth/image_raw",
    "camera/camera_info",
    "camera/pose",
    "sim/ground_truth/labels",
]


def publisher_qos(spec) -> QoSProfile:
    """The QoS a topic was recorded with, else reliable + volatile (matches every subscriber kind
    except transient-local ones, which get the recorded transient-local QoS when it was)."""
    if spec is None:
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=max(1, spec.depth),
        reliability=ReliabilityPolicy.RELIABLE if spec.reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if spec.transient_local else DurabilityPolicy.VOLATILE,
    )


class BagReplayer(Node):
    def __init__(self, **node_options):
        super().__init__("bag_replayer", **node_options)
        path = declare(self, "bag", "", "Bag to replay: a rosbag2 directory, .mcap or .db3")
        self.mode = declare(self, "mode", "original", "Timing", choices=["original", "consumed"])
        self.rate = declare(self, "rate", 1.0, "Playback speed factor of mode original", 0.01, 100.0)
        self.loop = declare(self, "loop", False, "Repeat the bag (header stamps keep increasing)")
        self.max_loops = declare(self, "max_loops", 0, "Passes through the bag with loop; 0 = until stopped", 0, 10**6)
        topics = declare(self, "topics", [""], "Topics to replay; [''] = every topic of the bag")
        start_offset_s = declare(self, "start_offset_s", 0.0, "Skip this much of the bag's start, seconds", 0.0, 1e7)
        duration_s = declare(self, "duration_s", 0.0, "Replay this much of the bag, seconds; 0 = to the end", 0.0, 1e7)
        self.publish_clock = declare(self, "publish_clock", True, "Publish /clock with the bag time")
        self.clock_rate_hz = declare(self, "clock_rate_hz", 100.0, "Most /clock messages per second", 1.0, 1000.0)
        frame_topics = declare(self, "frame_topics", list(FRAME_TOPICS), "Camera topics that make up a frame")
        consumed_topic = declare(self, "consumed_topic", "arm/meshes", "Output that marks a frame consumed")
        consumed_type = declare(
            self, "consumed_type", "arm_interfaces/msg/ReconstructedObjectArray", "Message type of consumed_topic"
        )
        self.consumed_timeout_s = declare(
            self, "consumed_timeout_s", 60.0, "Longest wait for a frame to be consumed, seconds", 0.1, 3600.0
        )
        self.first_frame_retry_s = declare(
            self,
            "first_frame_retry_s",
            20.0,
            "Mode consumed: re-publish the first frame this often until it is consumed (a link inside the "
            "pipeline that matched after it was sent lost it), seconds; 0 = never",
            0.0,
            3600.0,
        )
        self.wait_subscribers_s = declare(
            self, "wait_subscribers_s", 5.0, "Wait this long for subscribers before playing, seconds", 0.0, 600.0
        )
        self.linger_s = declare(self, "linger_s", 1.0, "Keep the publishers alive this long at the end", 0.0, 60.0)
        if not path:
            raise ValueError("parameter 'bag' (or the first argument) must name a bag")
        try:
            self.reader = BagReader(path)
        except BagError as error:
            raise ValueError(str(error)) from None
        selected = [self.resolve_topic_name(t) for t in topics if t]
        unknown = sorted(set(selected) - set(self.reader.topics))
        if unknown:
            raise ValueError(f"topics {unknown} are not in the bag (it has {sorted(self.reader.topics)})")
        self.topics = selected or sorted(self.reader.topics)
        self.start_ns = self.reader.start_ns + int(round(start_offset_s * 1e9))
        self.stop_ns = self.start_ns + int(round(duration_s * 1e9)) if duration_s > 0 else None
        self.frame_topics = {self.resolve_topic_name(t) for t in frame_topics if t}
        self.errors = RateLimitedErrors(self.get_logger())
        self.publishers_by_topic = {}
        for topic in self.topics:
            msgtype = self.reader.topics[topic]
            try:
                cls = message_class(msgtype)
            except BagError as error:
                raise ValueError(str(error)) from None
            self.publishers_by_topic[topic] = self.create_publisher(cls, topic, publisher_qos(self.reader.qos[topic]))
        self.pub_clock = self.create_publisher(Clock, "/clock", 10) if self.publish_clock else None
        self._consumed_ns = -1
        self._consumed = threading.Condition()
        if self.mode == "consumed":
            qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE)
            try:
                consumed_cls = message_class(consumed_type)
            except BagError as error:
                raise ValueError(str(error)) from None
            self.create_subscription(consumed_cls, consumed_topic, self.on_consumed, qos)
        self.consumed_topic = self.resolve_topic_name(consumed_topic)
        self.pub_diag = self.create_publisher(DiagnosticArray, "diagnostics", 10)
        self.published = {t: 0 for t in self.topics}
        self.frames_published = self.frames_consumed = self.frames_timed_out = self.corrupt = 0
        self.frames_incomplete = self.frames_republished = 0
        self._chain_proven = False  # a frame has been consumed: every link of the pipeline is matched
        self.passes = 0
        self._last_clock_wall = 0.0
        self.create_timer(1.0, self.publish_diagnostics)
        self.get_logger().info(
            f"replaying {path}: {self.reader.message_count} messages over "
            f"{self.reader.duration_ns * 1e-9:.2f} s, mode {self.mode}, topics {self.topics}"
        )

    # --- consumption -------------------------------------------------------------------------
    def on_consumed(self, msg) -> None:
        stamp = header_stamp_ns(msg)
        if stamp is None:
            return
        with self._consumed:
            self._consumed_ns = max(self._consumed_ns, stamp)
            self._consumed.notify_all()

    def wait_consumed(self, stamp_ns: int, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        with self._consumed:
            while self._consumed_ns < stamp_ns and rclpy.ok(context=self.context):
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self._consumed.wait(min(remaining, 0.1))
        return self._consumed_ns >= stamp_ns

    # --- playback ----------------------------------------------------------------------------
    def _sleep_until(self, wall_s: float) -> bool:
        while rclpy.ok(context=self.context):
            remaining = wall_s - time.monotonic()
            if remaining <= 0:
                return True
            time.sleep(min(remaining, 0.05))
        return False

    def _wait_for_subscribers(self) -> None:
        """Wait (at most wait_subscribers_s) for a subscriber on every replayed topic and, in mode
        consumed, for the publisher of consumed_topic: the end of the chain is up, then give the
        links in between one second to match."""
        deadline = time.monotonic() + self.wait_subscribers_s
        while time.monotonic() < deadline and rclpy.ok(context=self.context):
            subscribed = all(p.get_subscription_count() > 0 for p in self.publishers_by_topic.values())
            if subscribed and (self.mode != "consumed" or self.count_publishers(self.consumed_topic) > 0):
                if self.mode == "consumed":
                    time.sleep(1.0)
                return
            time.sleep(0.05)

    def _publish_clock(self, bag_ns: int, force: bool = False) -> None:
        now = time.monotonic()
        if self.pub_clock is not None and (force or now - self._last_clock_wall >= 1.0 / self.clock_rate_hz):
            self._last_clock_wall = now
            self.pub_clock.publish(Clock(clock=ns_to_time(bag_ns)))

    def play(self) -> None:
        self._wait_for_subscribers()
        stamps = LoopStamps()
        frame_topics = self.frame_topics & set(self.topics)
        groups = FrameGroups(frame_topics)
        pending_ns, pending = None, []  # header stamp and messages of the last frame published in mode consumed
        while rclpy.ok(context=self.context):
            offset_ns = stamps.offset_ns(self.passes)
            start_wall, first_ns = time.monotonic(), None
            for message in self.reader.messages(self.topics, self.start_ns, self.stop_ns):
                if not rclpy.ok(context=self.context):
                    return
                first_ns = message.timestamp_ns if first_ns is None else first_ns
                due = start_wall + (message.timestamp_ns - first_ns) * 1e-9 / self.rate
                if self.mode == "original" and not self._sleep_until(due):
                    return
                try:
                    msg = message.decode()
                except BagError as error:
                    self.corrupt += 1
                    self.errors.error("corrupt_message", f"skipping a message on {message.topic}: {error}")
                    continue
                stamp = header_stamp_ns(msg)
                stamps.observe(message.topic, message.timestamp_ns, stamp, self.passes)
                if offset_ns:
                    shift_stamps(msg, offset_ns)
                    stamp = header_stamp_ns(msg)
                bag_ns = message.timestamp_ns + offset_ns
                if self.mode == "original" or message.topic not in frame_topics or stamp is None:
                    self._publish(message.topic, msg, bag_ns)
                    if message.topic in frame_topics:
                        self.frames_published += stamp is not None and groups.new_stamp(stamp)
                    continue
                for frame_ns, frame in groups.add(message.topic, stamp, msg, bag_ns):
                    if pending_ns is not None:
                        self._finish_frame(pending_ns, pending)
                    for topic, frame_msg, frame_bag_ns in frame:
                        self._publish(topic, frame_msg, frame_bag_ns)
                    pending_ns, pending = frame_ns, frame
                    self.frames_published += 1
            self.passes += 1
            if not self.loop or (self.max_loops and self.passes >= self.max_loops):
                break
            if self.mode == "original" and not self._sleep_until(start_wall + stamps.period_ns() * 1e-9 / self.rate):
                return  # the next pass starts one bag period (span + one step) after this one
        if pending_ns is not None:
            self._finish_frame(pending_ns, pending)
        self.frames_incomplete = groups.dropped + len(groups.pending)
        self._sleep_until(time.monotonic() + self.linger_s)

    def _publish(self, topic: str, msg, bag_ns: int) -> None:
        self._publish_clock(bag_ns)
        self.publishers_by_topic[topic].publish(msg)
        self.published[topic] += 1

    def _finish_frame(self, stamp_ns: int, frame: list) -> None:
        """Wait until the frame is consumed; until some frame has been, re-publish it every
        first_frame_retry_s (discovery may match a link inside the pipeline after the send)."""
        deadline = time.monotonic() + self.consumed_timeout_s
        while True:
            remaining = deadline - time.monotonic()
            retry = not self._chain_proven and self.first_frame_retry_s > 0
            if self.wait_consumed(stamp_ns, min(remaining, self.first_frame_retry_s) if retry else remaining):
                self.frames_consumed += 1
                self._chain_proven = True
                return
            if not retry or deadline - time.monotonic() <= 0 or not rclpy.ok(context=self.context):
                break
            self.get_logger().warning(f"frame at {stamp_ns * 1e-9:.3f} s not consumed yet: publishing it again")
            self.frames_republished += 1
            for topic, frame_msg, frame_bag_ns in frame:
                self._publish(topic, frame_msg, frame_bag_ns)
        if rclpy.ok(context=self.context):
            self.frames_timed_out += 1
            self.errors.error(
                "not_consumed", f"frame at {stamp_ns * 1e-9:.3f} s not consumed within {self.consumed_timeout_s} s"
            )

    def publish_diagnostics(self) -> None:
        values = {
            "messages_published": sum(self.published.values()),
            "frames_published": self.frames_published,
            "frames_consumed": self.frames_consumed,
            "frames_timed_out": self.frames_timed_out,
            "frames_incomplete": self.frames_incomplete,
            "frames_republished": self.frames_republished,
            "corrupt_messages_skipped": self.corrupt,
            "passes": self.passes,
        }
        self.pub_diag.publish(diagnostics_msg(self, "replay", values))

    def summary(self) -> str:
        counts = ", ".join(f"{t}: {n}" for t, n in self.published.items())
        text = f"[replay] published {sum(self.published.values())} messages in {self.passes} pass(es) ({counts})"
        if self.mode == "consumed":
            text += f"; frames consumed {self.frames_consumed}, timed out {self.frames_timed_out}"
            text += f", incomplete (not published) {self.frames_incomplete}, republished {self.frames_republished}"
        if self.corrupt:
            text += f"; {self.corrupt} corrupt message(s) skipped"
        return text


def main(args=None) -> int:
    argv = remove_ros_args(args=sys.argv if args is None else args)[1:]
    if len(argv) > 1 or (argv and argv[0].startswith("-")):
        print("usage: replay BAG [--ros-args -p mode:=original|consumed -p rate:=1.0 -p loop:=true ...]")
        return 2
    use_large_socket_buffers()
    rclpy.init(args=args)  # rclpy's SIGINT/SIGTERM handlers shut the context down: play() then returns
    node = executor = spinner = None
    code = refused = 0
    try:
        overrides = [Parameter("bag", value=argv[0])] if argv else []
        node = BagReplayer(parameter_overrides=overrides)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        spinner = threading.Thread(target=spin_until_shutdown, args=(executor,), daemon=True)
        spinner.start()
        node.play()
        print(node.summary(), flush=True)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except BagError as error:  # the bag broke while playing: what was readable went out
        print(f"[replay] {error}", flush=True)
        if node is not None:
            print(node.summary(), flush=True)
        code = 2
    except (ValueError, ParameterException) as error:
        print(f"[bag_replayer] invalid configuration: {error}", flush=True)
        code = refused = 2
    except Exception:  # a publish that SIGINT/SIGTERM caught in flight
        if rclpy.ok():
            raise
    finally:
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        if spinner is not None:
            spinner.join(timeout=2.0)
        if node is not None:
            node.reader.close()
            node.destroy_node()
        rclpy.try_shutdown()
    if refused:
        exit_refused(refused)
    return code


if __name__ == "__main__":
    raise SystemExit(main())
