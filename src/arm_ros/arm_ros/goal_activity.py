"""Whether an action server is serving a goal, read from its status topic (<action>/_action/status).

Used to hold back heavy perception work while the planner plans (it shares the CPU). The pause ends
when no goal is accepted, executing or cancelling, when the server's status publisher is gone (a
planner that died mid-goal) or after `limit_s` (a goal that never ends).
"""

import time

from action_msgs.msg import GoalStatus, GoalStatusArray
from rclpy.qos import qos_profile_action_status_default

ACTIVE_STATES = (GoalStatus.STATUS_ACCEPTED, GoalStatus.STATUS_EXECUTING, GoalStatus.STATUS_CANCELING)


def active_goal_count(msg: GoalStatusArray) -> int:
    """Goals in `msg` that the server is still serving."""
    return sum(status.status in ACTIVE_STATES for status in msg.status_list)


class GoalActivity:
    """Tracks `action_name`'s goals on `node`; `on_change()` is called (from the executor) whenever
    the server's activity may have changed."""

    def __init__(self, node, action_name: str, limit_s: float, on_change=lambda: None):
        self.node = node
        self.topic = f"{action_name}/_action/status"
        self.limit_s = float(limit_s)
        self.on_change = on_change
        self.active_since_s: float | None = None  # time.monotonic() when a goal became active
        self.pauses = 0
        node.create_subscription(GoalStatusArray, self.topic, self._on_status, qos_profile_action_status_default)

    def _on_status(self, msg: GoalStatusArray) -> None:
        if active_goal_count(msg) == 0:
            self.active_since_s = None
        elif self.active_since_s is None:
            self.active_since_s = time.monotonic()
            self.pauses += 1
        self.on_change()

    def seconds_left(self) -> float:
        """Seconds the pause may still last (0: not paused)."""
        if self.active_since_s is None or self.node.count_publishers(self.topic) == 0:
            return 0.0
        return max(0.0, self.active_since_s + self.limit_s - time.monotonic())
