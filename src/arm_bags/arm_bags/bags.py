"""rosbag2 storage (mcap or sqlite3) for the project's topics, without a ROS install.

Bags are written and read with the pure-Python `rosbags` package in the rosbag2 directory layout
(metadata.yaml + one .mcap or .db3 file), readable by `ros2 bag info/play` on a full ROS 2 install.
Messages are stored as the CDR bytes rclpy itself produces; the message definitions (the standard
Jazzy set plus arm_interfaces) come from a rosbags typestore. Timestamps are integer nanoseconds.

The stamp helpers at the end serve replay: header stamps in nanoseconds,
shifting them, the per-pass offset of a looping bag and grouping camera messages into frames.
"""

from __future__ import annotations

import importlib
import os
import pathlib
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from functools import lru_cache

from rclpy.serialization import deserialize_message, serialize_message
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import Reader, StoragePlugin, Writer, WriterError
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from arm_ros.conversions.stamps import ns_to_time, time_ns

STORAGE_PLUGINS = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
STORAGE_SUFFIXES = {".mcap": "mcap", ".db3": "sqlite3"}
ROSBAG2_VERSION = 9  # the metadata version rosbag2 writes on Jazzy
INTERFACE_PACKAGES = ("arm_interfaces",)


class BagError(RuntimeError):
    """A bag could not be opened, read or written: missing, corrupt, truncated or of unknown types."""


def _interface_msg_dirs(package: str) -> list[pathlib.Path]:
    """Directories holding `package`'s .msg files: installed share/ dirs first, then the source tree."""
    dirs = []
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            dirs.append(pathlib.Path(prefix) / "share" / package / "msg")
    dirs.append(pathlib.Path(__file__).resolve().parents[2] / package / "msg")
    return [d for d in dirs if d.is_dir() and any(d.glob("*.msg"))]


@lru_cache(maxsize=1)
def project_typestore():
    """The ROS 2 Jazzy typestore extended with the arm_interfaces message definitions."""
    store = get_typestore(Stores.ROS2_JAZZY)
    for package in INTERFACE_PACKAGES:
        dirs = _interface_msg_dirs(package)
        if not dirs:
            continue
        types = {}
        for path in sorted(dirs[0].glob("*.msg")):
            types.update(get_types_from_msg(path.read_text(), f"{package}/msg/{path.stem}"))
        store.register(types)
    return store


def msgtype_name(msg_or_class) -> str:
    """rclpy message (or class) -> 'pkg/msg/Name'."""
    cls = msg_or_class if isinstance(msg_or_class, type) else type(msg_or_class)
    package = cls.__module__.split(".")[0]
    return f"{package}/msg/{cls.__name__}"


def message_class(msgtype: str):
    """'pkg/msg/Name' -> the generated Python message class. Raises BagError if it is not installed."""
    try:
        package, kind, name = msgtype.split("/")
        return getattr(importlib.import_module(f"{package}.{kind}"), name)
    except (ValueError, ImportError, AttributeError) as error:
        raise BagError(f"message type '{msgtype}' is not available in this environment: {error}") from None


def serialize(msg) -> bytes:
    return serialize_message(msg)


def deserialize(raw: bytes, msgtype: str):
    """CDR bytes -> rclpy message. Raises BagError on bytes that do not decode as msgtype."""
    cls = message_class(msgtype)
    try:
        return deserialize_message(bytes(raw), cls)
    except Exception as error:  # rclpy raises a bare RuntimeError/Exception from C
        raise BagError(f"corrupt {msgtype} message ({len(raw)} bytes): {error}") from None


@dataclass(frozen=True)
class QosSpec:
    """The QoS a topic was offered with, as far as a bag stores it."""

    reliable: bool = True
    transient_local: bool = False
    depth: int = 10

    def to_rosbags(self) -> Qos:
        zero = QosTime(sec=0, nsec=0)
        return Qos(
            history=QosHistory.KEEP_LAST,
            depth=self.depth,
            reliability=QosReliability.RELIABLE if self.reliable else QosReliability.BEST_EFFORT,
            durability=QosDurability.TRANSIENT_LOCAL if self.transient_local else QosDurability.VOLATILE,
            deadline=zero,
            lifespan=zero,
            liveliness=QosLiveliness.AUTOMATIC,
            liveliness_lease_duration=zero,
            avoid_ros_namespace_conventions=False,
        )

    @staticmethod
    def from_rosbags(profiles: Sequence[Qos]) -> QosSpec | None:
        if not profiles:
            return None
        reliable = all(p.reliability == QosReliability.RELIABLE for p in profiles)
        latched = any(p.durability == QosDurability.TRANSIENT_LOCAL for p in profiles)
        depth = max(int(p.depth) for p in profiles) or 10
        return QosSpec(reliable=reliable, transient_local=latched, depth=depth)


@dataclass(frozen=True)
class BagMessage:
    topic: str
    msgtype: str
    timestamp_ns: int
    raw: bytes

    def decode(self):
        return deserialize(self.raw, self.msgtype)


class BagWriter:
    """Write CDR messages to a new rosbag2 directory. Use as a context manager (or call close())."""

    def __init__(self, path, storage: str = "mcap"):
        if storage not in STORAGE_PLUGINS:
            raise BagError(f"storage must be one of {sorted(STORAGE_PLUGINS)}, got '{storage}'")
        self.path = pathlib.Path(path)
        self.storage = storage
        self.typestore = project_typestore()
        try:
            self._writer = Writer(self.path, version=ROSBAG2_VERSION, storage_plugin=STORAGE_PLUGINS[storage])
            self._writer.open()
        except (WriterError, OSError) as error:
            raise BagError(f"cannot create bag {self.path}: {error}") from None
        self._connections: dict[str, object] = {}
        self.counts: dict[str, int] = {}

    def add_topic(self, topic: str, msgtype: str, qos: QosSpec | None = None) -> None:
        if topic in self._connections:
            return
        if msgtype not in self.typestore.fielddefs:
            raise BagError(f"no message definition for '{msgtype}' (topic {topic})")
        profiles = [qos.to_rosbags()] if qos is not None else []
        self._connections[topic] = self._writer.add_connection(
            topic, msgtype, typestore=self.typestore, offered_qos_profiles=profiles
        )
        self.counts[topic] = 0

    def write(self, topic: str, timestamp_ns: int, raw: bytes, msgtype: str | None = None) -> None:
        """Append one serialized message; the topic is added on first use when msgtype is given."""
        if topic not in self._connections:
            if msgtype is None:
                raise BagError(f"topic {topic} was not added to the bag")
            self.add_topic(topic, msgtype)
        self._writer.write(self._connections[topic], int(timestamp_ns), bytes(raw))
        self.counts[topic] += 1

    def write_message(self, topic: str, timestamp_ns: int, msg, qos: QosSpec | None = None) -> None:
        if topic not in self._connections:
            self.add_topic(topic, msgtype_name(msg), qos)
        self.write(topic, timestamp_ns, serialize(msg))

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _storage_path(path: pathlib.Path) -> pathlib.Path:
    """A bag directory with metadata.yaml, or its single storage file when metadata.yaml is missing
    (a recording that was killed before it could finish writing), or a bare .mcap/.db3 file."""
    if not path.exists():
        raise BagError(f"bag {path} does not exist")
    if path.is_dir() and not (path / "metadata.yaml").exists():
        files = [p for p in sorted(path.iterdir()) if p.suffix in STORAGE_SUFFIXES]
        if len(files) != 1:
            raise BagError(f"{path} is not a rosbag2 directory (no metadata.yaml, {len(files)} storage files)")
        return files[0]
    if path.is_file() and path.suffix not in STORAGE_SUFFIXES:
        raise BagError(f"{path}: unknown bag storage '{path.suffix}' (expected a directory, .mcap or .db3)")
    return path


class BagReader:
    """Read a rosbag2 bag (directory, .mcap or .db3). Every failure is a BagError with the reason."""

    def __init__(self, path):
        self.path = pathlib.Path(path)
        storage_path = _storage_path(self.path)
        try:
            self._reader = Reader(storage_path)
            self._reader.open()
        except Exception as error:  # rosbags raises ReaderError, yaml, sqlite3 and struct errors alike
            raise BagError(f"cannot open bag {self.path}: {type(error).__name__}: {error}") from None
        self.topics: dict[str, str] = {c.topic: c.msgtype for c in self._reader.connections}
        self.qos: dict[str, QosSpec | None] = {
            c.topic: QosSpec.from_rosbags(getattr(c.ext, "offered_qos_profiles", ())) for c in self._reader.connections
        }
        self.message_counts: dict[str, int] = {}
        for c in self._reader.connections:
            self.message_counts[c.topic] = self.message_counts.get(c.topic, 0) + int(c.msgcount)

    @property
    def start_ns(self) -> int:
        return int(self._reader.start_time) if self.message_count else 0

    @property
    def duration_ns(self) -> int:
        return max(0, int(self._reader.duration) - 1) if self.message_count else 0

    @property
    def message_count(self) -> int:
        return int(self._reader.message_count)

    def messages(
        self, topics: Iterable[str] | None = None, start_ns: int | None = None, stop_ns: int | None = None
    ) -> Iterator[BagMessage]:
        """Messages in timestamp order, optionally only those of `topics` stamped in [start_ns, stop_ns)."""
        wanted = None if topics is None else set(topics)
        connections = [c for c in self._reader.connections if wanted is None or c.topic in wanted]
        if not connections:
            return
        try:
            for connection, timestamp, raw in self._reader.messages(connections, start=start_ns, stop=stop_ns):
                yield BagMessage(connection.topic, connection.msgtype, int(timestamp), bytes(raw))
        except Exception as error:  # ReaderError, struct.error, sqlite3.DatabaseError, zstd errors, ...
            raise BagError(f"bag {self.path} is corrupt or truncated: {type(error).__name__}: {error}") from None

    def close(self) -> None:
        self._reader.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def write_bag(path, messages: Iterable[tuple[str, int, object]], storage: str = "mcap") -> dict[str, int]:
    """Write (topic, timestamp_ns, rclpy message) triples to a new bag; returns messages per topic."""
    with BagWriter(path, storage) as writer:
        for topic, timestamp_ns, msg in messages:
            writer.write_message(topic, timestamp_ns, msg)
        return dict(writer.counts)


def read_bag(path, topics: Iterable[str] | None = None) -> list[tuple[str, int, object]]:
    """All (topic, timestamp_ns, rclpy message) triples of a bag, in timestamp order."""
    with BagReader(path) as reader:
        return [(m.topic, m.timestamp_ns, m.decode()) for m in reader.messages(topics)]


# --- stamps (replay) ------------------------------------------------------------------------
def header_stamp_ns(msg) -> int | None:
    """The stamp of msg.header (or of a rosgraph_msgs/Clock), nanoseconds; None without one."""
    header = getattr(msg, "header", None)
    if header is not None and hasattr(header, "stamp"):
        return time_ns(header.stamp)
    clock = getattr(msg, "clock", None)
    return time_ns(clock) if clock is not None and hasattr(clock, "nanosec") else None


def shift_stamps(msg, offset_ns: int) -> None:
    """Add offset_ns to msg.header.stamp (or Clock.clock) in place."""
    stamp = header_stamp_ns(msg)
    if stamp is None:
        return
    shifted = ns_to_time(stamp + offset_ns)
    if getattr(msg, "header", None) is not None:
        msg.header.stamp = shifted
    else:
        msg.clock = shifted


class LoopStamps:
    """Observes the first pass through a bag and gives each later pass a stamp offset of one bag
    period: the larger of the receive-time and header-stamp spans plus one typical stamp step."""

    def __init__(self):
        self.bag_ns = [None, None]
        self.header_ns = [None, None]
        self._last_stamp: dict[str, int] = {}
        self._steps: dict[str, int] = {}

    @staticmethod
    def _extend(bounds, value):
        bounds[0] = value if bounds[0] is None else min(bounds[0], value)
        bounds[1] = value if bounds[1] is None else max(bounds[1], value)

    def observe(self, topic: str, bag_ns: int, stamp_ns: int | None, pass_index: int) -> None:
        if pass_index:
            return
        self._extend(self.bag_ns, bag_ns)
        if stamp_ns is None:
            return
        self._extend(self.header_ns, stamp_ns)
        if self._last_stamp.get(topic, stamp_ns) != stamp_ns:
            self._steps[topic] = self._steps.get(topic, 0) + 1
        self._last_stamp[topic] = stamp_ns

    def period_ns(self) -> int:
        spans = [b[1] - b[0] for b in (self.bag_ns, self.header_ns) if b[0] is not None]
        span = max(spans, default=0)
        steps = max(self._steps.values(), default=0)
        step = span // steps if steps else 0
        return span + max(step, 1_000_000)

    def offset_ns(self, pass_index: int) -> int:
        return 0 if pass_index == 0 else pass_index * self.period_ns()


class FrameGroups:
    """Groups camera messages into frames by header stamp. A frame is released once it holds one
    message of each frame topic; older groups still incomplete by then are dropped (they would be
    stale for any time synchronizer), as is the oldest group when more than max_pending wait."""

    def __init__(self, topics, max_pending: int = 16):
        self.topics = frozenset(topics)
        self.max_pending = max_pending
        self.pending: dict[int, dict[str, tuple]] = {}
        self.dropped = 0
        self._last_stamp = None

    def new_stamp(self, stamp_ns: int) -> bool:
        """True the first time a stamp shows up (frame counting without grouping)."""
        new = stamp_ns != self._last_stamp
        self._last_stamp = stamp_ns
        return new

    def add(self, topic: str, stamp_ns: int, msg, bag_ns: int) -> list[tuple[int, list[tuple]]]:
        """Add one message; returns the frames completed by it as (stamp, [(topic, msg, bag_ns)])."""
        group = self.pending.setdefault(stamp_ns, {})
        group[topic] = (topic, msg, bag_ns)
        if set(group) != self.topics:
            if len(self.pending) > self.max_pending:
                del self.pending[min(self.pending)]
                self.dropped += 1
            return []
        for older in [s for s in self.pending if s < stamp_ns]:
            del self.pending[older]
            self.dropped += 1
        frame = self.pending.pop(stamp_ns)
        return [(stamp_ns, sorted(frame.values(), key=lambda entry: entry[2]))]
