"""builtin_interfaces/Time <-> integer nanoseconds (exact: stamps used as keys stay equal)."""

from builtin_interfaces.msg import Time


def time_ns(stamp) -> int:
    """A builtin_interfaces/Time (or anything with sec and nanosec) -> integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_time(ns: int) -> Time:
    """Integer nanoseconds (negative: 0) -> builtin_interfaces/Time."""
    ns = max(0, int(ns))
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
