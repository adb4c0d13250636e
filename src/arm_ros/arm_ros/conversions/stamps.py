"""builtin_interfaces/Time and Duration <-> integer nanoseconds (exact: stamps used as keys stay equal)."""

import math

from builtin_interfaces.msg import Duration, Time


def time_ns(stamp) -> int:
    """A builtin_interfaces/Time (or anything with sec and nanosec) -> integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_time(ns: int) -> Time:
    """Integer nanoseconds (negative: 0) -> builtin_interfaces/Time."""
    ns = max(0, int(ns))
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def seconds_to_duration(seconds: float) -> Duration:
    """Seconds -> builtin_interfaces/Duration, rounded to the nearest nanosecond as a whole (so 0.9999999999 s
    is 1 s, not 0 s plus a wrapped nanosecond field). Raises ValueError for a non-finite or negative time."""
    if not math.isfinite(seconds) or seconds < 0:
        raise ValueError(f"duration must be finite and >= 0 s, got {seconds}")
    ns = int(round(seconds * 1e9))
    return Duration(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def cdr_header_stamp_ns(serialized: bytes) -> int | None:
    """The header stamp (integer nanoseconds) of a serialized message whose first field is a
    std_msgs/Header, read from its CDR bytes without deserializing the rest (an image is about 1 MB);
    None when the bytes are too short or not plain CDR (encapsulation 0x0000 big or 0x0001 little
    endian), where the caller deserializes the message instead."""
    if len(serialized) < 12 or serialized[0] != 0 or serialized[1] not in (0, 1) or serialized[2:4] != b"\0\0":
        return None
    order = "little" if serialized[1] == 1 else "big"
    sec = int.from_bytes(serialized[4:8], order, signed=True)
    return sec * 1_000_000_000 + int.from_bytes(serialized[8:12], order)
