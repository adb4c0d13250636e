"""/tf and /tf_static: a publisher, and a listener (tf2_ros's where it is installed, else one that
chains the latest transforms).

The Python-wheel install has no tf2_ros (nor tf2_msgs, which compat/ builds with the same definition,
so the wire type matches a full ROS 2 install's). These speak tf2's topics with tf2_ros's QoS: a robot's
TF tree (robot_state_publisher, a camera driver, a calibration) reaches the nodes, and RViz or tf2_ros
see what they publish. The listener keeps the latest transform of each frame from its parent (no
interpolation in time: the newest wins) and chains them through the tree; it holds at most
max_frames frames. Where tf2_ros can be imported (a full ROS 2 install), `tf_listener` gives tf2_ros's
buffer behind the same two methods instead.
"""

import re
from collections import OrderedDict, deque

import numpy as np
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

from arm_ros.conversions import ConversionError
from arm_ros.conversions.poses import transform_msg_to_matrix

TF_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE)
TF_STATIC_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)


class TfPublisher:
    """Publishes transforms on /tf (moving frames) and /tf_static (latched: each static message holds
    every static transform this publisher has sent, as tf2_ros's static broadcaster does)."""

    def __init__(self, node):
        self.dynamic = node.create_publisher(TFMessage, "/tf", TF_QOS)
        self.static = node.create_publisher(TFMessage, "/tf_static", TF_STATIC_QOS)
        self._static_transforms: dict[str, object] = {}

    def send(self, transforms) -> None:
        if transforms:
            self.dynamic.publish(TFMessage(transforms=list(transforms)))

    def send_static(self, transforms) -> None:
        for t in transforms:
            self._static_transforms[t.child_frame_id] = t
        self.static.publish(TFMessage(transforms=list(self._static_transforms.values())))


class TfListener:
    """The latest transform between any two connected frames of /tf and /tf_static."""

    def __init__(self, node, max_frames: int = 1000):
        self.max_frames = int(max_frames)
        self._parent: OrderedDict[str, tuple[str, np.ndarray]] = OrderedDict()  # child -> (parent, T_parent_child)
        node.create_subscription(TFMessage, "/tf", self.on_message, TF_QOS)
        node.create_subscription(TFMessage, "/tf_static", self.on_message, TF_STATIC_QOS)

    def on_message(self, msg: TFMessage) -> None:
        for t in msg.transforms:
            child, parent = t.child_frame_id.lstrip("/"), t.header.frame_id.lstrip("/")
            if not child or not parent or child == parent:
                continue
            try:
                T = transform_msg_to_matrix(t)
            except ConversionError:
                continue  # a malformed transform is skipped, the rest of the message is kept
            self._parent[child] = (parent, T)
            self._parent.move_to_end(child)
            while len(self._parent) > self.max_frames:
                self._parent.popitem(last=False)

    def frames(self) -> set[str]:
        return set(self._parent) | {parent for parent, _ in self._parent.values()}

    def lookup(self, target: str, source: str) -> np.ndarray | None:
        """4x4 T_target_source (a point in source's frame, expressed in target's), or None when the two
        frames are not connected."""
        target, source = target.lstrip("/"), source.lstrip("/")
        if target == source:
            return np.eye(4)
        neighbours: dict[str, list[tuple[str, np.ndarray]]] = {}
        for child, (parent, T) in self._parent.items():
            neighbours.setdefault(parent, []).append((child, T))  # T_parent_child
            neighbours.setdefault(child, []).append((parent, np.linalg.inv(T)))  # T_child_parent
        seen, queue = {target}, deque([(target, np.eye(4))])
        while queue:
            frame, T_target_frame = queue.popleft()
            for other, T_frame_other in neighbours.get(frame, []):
                if other in seen:
                    continue
                T_target_other = T_target_frame @ T_frame_other
                if other == source:
                    return T_target_other
                seen.add(other)
                queue.append((other, T_target_other))
        return None


class Tf2RosListener:
    """tf2_ros's Buffer and TransformListener behind TfListener's methods (the latest transforms)."""

    def __init__(self, node, tf2_ros):
        self._tf2_ros = tf2_ros
        self.buffer = tf2_ros.Buffer()
        self.listener = tf2_ros.TransformListener(self.buffer, node)

    def frames(self) -> set[str]:
        return set(re.findall(r"Frame (\S+) exists", self.buffer.all_frames_as_string()))

    def lookup(self, target: str, source: str) -> np.ndarray | None:
        from rclpy.time import Time

        try:
            transform = self.buffer.lookup_transform(target.lstrip("/"), source.lstrip("/"), Time())
        except self._tf2_ros.TransformException:
            return None
        try:
            return transform_msg_to_matrix(transform)
        except ConversionError:
            return None


def tf_listener(node):
    """tf2_ros's listener where tf2_ros is installed, else TfListener: either has frames() and
    lookup(target, source) -> 4x4 T_target_source or None."""
    try:
        import tf2_ros
    except ImportError:
        return TfListener(node)
    return Tf2RosListener(node, tf2_ros)
