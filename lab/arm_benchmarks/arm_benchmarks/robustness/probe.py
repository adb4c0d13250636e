"""An in-process DDS probe: an rclpy node in its own context, spun by a background thread."""

from __future__ import annotations

import threading
import time
from collections import deque

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor

from arm_ros.common import spin_until_shutdown


class Probe:
    """An rclpy node in its own context, spun by a background thread: publishers for inputs,
    recorders of outputs and of /diagnostics."""

    def __init__(self, name: str = "robustness_probe"):
        self._rclpy = rclpy
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.lock = threading.Lock()
        self.diagnostics: dict[str, dict[str, str]] = {}
        self.diagnostics_history: dict[str, deque] = {}
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        spin_until_shutdown(self.executor)

    def publisher(self, msg_type, topic: str, qos=10):
        return self.node.create_publisher(msg_type, topic, qos)

    def record(self, msg_type, topic: str, qos=10, keep: int | None = None, on_message=None):
        """Messages received on topic, in a list (or a deque of the last `keep`), with their arrival
        times (time.monotonic) in the parallel `.times` attribute, the running count in `.total` and
        the rclpy subscription in `.subscription`."""
        store = _Recorded(keep)

        def callback(msg):
            with self.lock:
                store.append(msg)
                store.times.append(time.monotonic())
                store.total += 1
            if on_message is not None:
                on_message(msg)

        store.subscription = self.node.create_subscription(msg_type, topic, callback, qos)
        return store

    def watch_diagnostics(self, history: int = 2000) -> None:
        def callback(msg):
            with self.lock:
                for status in msg.status:
                    values = {kv.key: kv.value for kv in status.values}
                    values["_level"] = str(
                        int.from_bytes(status.level, "little") if isinstance(status.level, bytes) else int(status.level)
                    )
                    values["_message"] = status.message
                    values["_received_s"] = str(time.monotonic())
                    self.diagnostics[status.name] = values
                    self.diagnostics_history.setdefault(status.name, deque(maxlen=history)).append(values)

        self.node.create_subscription(DiagnosticArray, "/diagnostics", callback, 100)

    def diagnostic(self, node_name: str) -> dict[str, str]:
        """Latest diagnostics values of the status whose name starts with node_name."""
        with self.lock:
            for name, values in self.diagnostics.items():
                if name.startswith(node_name + ":"):
                    return dict(values)
        return {}

    def diagnostic_number(self, node_name: str, key: str, default: float = float("nan")) -> float:
        try:
            return float(self.diagnostic(node_name).get(key, default))
        except ValueError:
            return default

    def in_executor(self, fn, timeout_s: float = 10.0):
        """Run fn() on the executor thread and return its value. rclpy's ActionClient is not thread
        safe: a goal or result response taken between send_*_request and the registration of its
        future is dropped ('Ignoring unexpected goal response'), so requests go out from there."""
        done, out = threading.Event(), {}

        def task():
            try:
                out["value"] = fn()
            except Exception as error:  # handed back to the caller
                out["error"] = error
            finally:
                done.set()

        self.executor.create_task(task)
        if not done.wait(timeout_s):
            raise TimeoutError("the probe's executor did not run the task")
        if "error" in out:
            raise out["error"]
        return out["value"]

    def wait_until(self, predicate, timeout_s: float, poll_s: float = 0.05) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if predicate():
                return True
            time.sleep(poll_s)
        return bool(predicate())

    def wait_for_subscribers(self, publishers, timeout_s: float = 30.0) -> bool:
        return self.wait_until(lambda: all(p.get_subscription_count() > 0 for p in publishers), timeout_s)

    def close(self) -> None:
        self._rclpy.try_shutdown(context=self.context)  # the spin thread returns quietly
        self._thread.join(timeout=2.0)
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()


class _Recorded(deque):
    def __init__(self, keep):
        super().__init__(maxlen=keep)
        self.times = deque(maxlen=keep)
        self.total = 0
        self.subscription = None
