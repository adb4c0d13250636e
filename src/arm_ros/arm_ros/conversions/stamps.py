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
