"""Node plumbing shared by every ARM node: QoS profiles, declared parameters, rate-limited error
logs, diagnostics and a clean main loop. Imports rclpy: node modules only, never the cores."""

import faulthandler
import os
import random
import re
import sys
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

from arm_core.heap import freeze_startup_objects
from arm_core.settings import parameters_of, with_values


def use_private_domain() -> int:
    """Put this process and the nodes it starts on a random DDS domain, unless ROS_DOMAIN_ID is set,
    talking over localhost only; returns the domain. Domains 1-101 only: their UDP ports lie below
    Linux's ephemeral port range (32768-60999), where higher domains' ports can be taken."""
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 101)))
    os.environ.setdefault("ROS_LOCALHOST_ONLY", "1")
    return int(os.environ["ROS_DOMAIN_ID"])


# Fast DDS's socket buffers for the nodes' processes, bytes: room for two 640x480 colour + depth
# frames (2.1 MB each). A best-effort image is fragmented over UDP, and one fragment the socket cannot
# hold loses the whole image: with the system's default 208 KB, a niced node that fell behind its
# socket received about a third of the depth images of a 30 Hz camera (docs/experiments.md). The
# kernel caps the size at net.core.rmem_max.
DDS_SOCKET_BUFFER_BYTES = 4 * 1024 * 1024


def use_large_socket_buffers() -> str | None:
    """Before rclpy.init: Fast DDS's built-in transports set to UDP with DDS_SOCKET_BUFFER_BYTES socket
    buffers (FASTDDS_BUILTIN_TRANSPORTS), unless another RMW, an XML profile or transport options are
    given; a mode already named (UDPv4, DEFAULT, ...) keeps its name. Returns the setting made, or None."""
    if os.environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp") != "rmw_fastrtps_cpp":
        return None
    if os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE") or os.environ.get("FASTDDS_DEFAULT_PROFILES_FILE"):
        return None
    mode = os.environ.get("FASTDDS_BUILTIN_TRANSPORTS", "") or "UDPv4"
    if "?" in mode:
        return None
    os.environ["FASTDDS_BUILTIN_TRANSPORTS"] = f"{mode}?sockets_size={DDS_SOCKET_BUFFER_BYTES}"
    return os.environ["FASTDDS_BUILTIN_TRANSPORTS"]


def sensor_qos(reliability: str = "best_effort", depth: int = 2) -> QoSProfile:
    """The sensor-data profile (keep-last, volatile) with a configurable reliability."""
    if reliability not in ("best_effort", "reliable"):
        raise ValueError(f"reliability must be 'best_effort' or 'reliable', got '{reliability}'")
    qos = QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        durability=qos_profile_sensor_data.durability,
        reliability=ReliabilityPolicy.BEST_EFFORT if reliability == "best_effort" else ReliabilityPolicy.RELIABLE,
    )
    return qos


def latched_qos(depth: int = 1) -> QoSProfile:
    """Reliable + transient-local: late subscribers still get the last message (meshes, ground truth)."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )


def declare(node, name: str, default, description: str, low=None, high=None, choices=None):
    """Declare a parameter with a descriptor (and range) and return its value, validated. The nodes
    read their parameters once, at start-up, so each is declared read-only: `ros2 param set` is
    refused with "read-only" instead of reporting success and changing nothing."""
    descriptor = ParameterDescriptor(description=description, read_only=True)
    if low is not None and isinstance(default, bool) is False:
        if isinstance(default, int):
            descriptor.integer_range = [IntegerRange(from_value=int(low), to_value=int(high), step=0)]
        elif isinstance(default, float):
            descriptor.floating_point_range = [
                FloatingPointRange(from_value=float(low), to_value=float(high), step=0.0)
            ]
    if choices:
        descriptor.additional_constraints = "one of: " + ", ".join(choices)
    value = node.declare_parameter(name, default, descriptor).value
    if choices and value not in choices:
        raise ValueError(f"parameter '{name}'='{value}' is not one of {choices}")
    return value


def declare_settings(node, config):
    """Declare the settings of a core's config dataclass that are marked as parameters
    (arm_core.settings), with their descriptions and ranges; returns config with the values given."""
    values = {
        s.name: declare(node, s.name, s.value, s.description, s.low, s.high, s.choices) for s in parameters_of(config)
    }
    return with_values(config, values)


def lower_cpu_priority(niceness: int) -> int:
    """Lower this process's CPU priority to `niceness` (Linux 0-19; a process can lower its own
    priority, not raise it); returns the niceness in effect."""
    current = os.nice(0)
    if niceness > current:
        current = os.nice(niceness - current)
    return current


class RateLimitedErrors:
    """Log each distinct error cause at most once per period_s, counting the suppressed repeats.

    Numbers in a cause are ignored when telling causes apart (so "depth 480x640 != rgb 240x320" is one
    cause whatever the sizes), and at most max_causes causes are tracked: memory stays bounded."""

    def __init__(self, logger, period_s: float = 5.0, max_causes: int = 256):
        self.logger, self.period_s, self.max_causes = logger, period_s, max_causes
        self._last: dict[str, float] = {}
        self.counts: dict[str, int] = {}

    def error(self, cause: str, message: str) -> None:
        key = _NUMBER.sub("#", cause)
        if key not in self.counts and len(self.counts) >= self.max_causes:
            key = "other"
        self.counts[key] = self.counts.get(key, 0) + 1
        now = time.monotonic()
        if now - self._last.get(key, -1e9) >= self.period_s:
            self._last[key] = now
            self.logger.error(f"{message} [{cause}, seen {self.counts[key]}x]")


_NUMBER = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?|nan|inf", re.IGNORECASE)


def diagnostics_msg(node, name: str, values: dict, level=DiagnosticStatus.OK, message: str = "ok") -> DiagnosticArray:
    status = DiagnosticStatus(
        level=level,
        name=f"{node.get_name()}: {name}",
        message=message,
        hardware_id=node.get_fully_qualified_name(),
        values=[KeyValue(key=str(k), value=f"{v:.4g}" if isinstance(v, float) else str(v)) for k, v in values.items()],
    )
    array = DiagnosticArray(status=[status])
    array.header.stamp = node.get_clock().now().to_msg()
    return array


def spin_until_shutdown(executor) -> None:
    """executor.spin() until SIGINT/SIGTERM, returning quietly also when the shutdown caught a take or
    a callback in flight (rclpy then raises RCLError / RuntimeError from that call)."""
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if executor.context.ok():
            raise


def _node_refused_in_constructor(error: BaseException):
    """The node whose constructor raised error (the innermost rclpy Node with a handle bound to `self`
    in the traceback), so that the message can name it; None if there is none."""
    found, tb = None, error.__traceback__
    while tb is not None:
        candidate = tb.tb_frame.f_locals.get("self")
        if isinstance(candidate, Node) and hasattr(candidate, "_Node__node"):
            found = candidate
        tb = tb.tb_next
    return found


def run_node(node_factory, args=None, executor_factory=None) -> int:
    """Run a node until SIGINT/SIGTERM and shut down cleanly; returns the exit code. An invalid
    parameter value or type (rclpy's
    ParameterException, raised by declare_parameter on a range or type violation) exits the process
    with code 2 and one clear line instead of a traceback, and errors that SIGINT/SIGTERM provoke in a callback
    or take in flight end the process cleanly (exit code 0). A fatal signal (a crash in native code)
    writes every thread's Python stack to stderr, the node's log, before the process dies. Once the
    node is built, its start-up objects are frozen out of the garbage collector's scans
    (arm_core.heap)."""
    faulthandler.enable()
    use_large_socket_buffers()
    rclpy.init(args=args)
    node = None
    code = 0
    try:
        node = node_factory()
        executor = executor_factory() if executor_factory is not None else SingleThreadedExecutor()
        executor.add_node(node)
        freeze_startup_objects()
        spin_until_shutdown(executor)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ValueError, ParameterException) as error:
        named = node or _node_refused_in_constructor(error)
        name = named.get_name() if named is not None else "node"
        print(f"[{name}] invalid configuration: {error}", flush=True)
        code = 2
    except Exception:
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            close = getattr(node, "close", None)
            if close is not None:
                close()
            node.destroy_node()
        rclpy.try_shutdown()
    if code == 2:
        exit_refused(code)
    return code


def exit_refused(code: int = 2) -> None:
    """End a process whose node was refused at start-up, after rclpy's shutdown: flush and leave at
    once rather than through interpreter teardown, which once hung under load (a node refused in its
    constructor is never destroyed before it)."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
