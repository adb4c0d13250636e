"""Whether the planner is planning a goal, read from its action's status and feedback topics
(<action>/_action/status, <action>/_action/feedback).

Used to hold back heavy perception work while the planner plans (it shares the CPU). The pause ends
when every goal still accepted, executing or cancelling has reported `executing` in its feedback
(planning is over, the robot moves and a new frame may show the result), when the server's status
publisher is gone (a planner that died mid-goal) or after `limit_s` (a goal that never ends).
"""

import time

from action_msgs.msg import GoalStatus, GoalStatusArray
from rclpy.qos import qos_profile_action_status_default

from arm_core.settings import GoalPauseSettings
from arm_interfaces.action import Manipulate

ACTIVE_STATES = (GoalStatus.STATUS_ACCEPTED, GoalStatus.STATUS_EXECUTING, GoalStatus.STATUS_CANCELING)


def active_goal_ids(msg: GoalStatusArray) -> set[bytes]:
    """Ids of the goals in `msg` that the server is still serving."""
    return {bytes(s.goal_info.goal_id.uuid) for s in msg.status_list if s.status in ACTIVE_STATES}


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
        self.active: set[bytes] = set()  # goals being served
        self.executing: set[bytes] = set()  # of those, the ones whose planning is over
        node.create_subscription(GoalStatusArray, self.topic, self._on_status, qos_profile_action_status_default)
        node.create_subscription(
            Manipulate.Impl.FeedbackMessage, f"{action_name}/_action/feedback", self._on_feedback, 10
        )

    def _on_status(self, msg: GoalStatusArray) -> None:
        self.active = active_goal_ids(msg)
        self.executing &= self.active
        self._update()

    def _on_feedback(self, msg) -> None:
        if msg.feedback.executing:
            self.executing.add(bytes(msg.goal_id.uuid))
            self._update()

    def _update(self) -> None:
        if not (self.active - self.executing):
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


def goal_pause(node, settings: GoalPauseSettings, on_change=lambda: None) -> "GoalActivity | None":
    """The tracker of the planner's goals when settings.pause_during_goals is on, else None."""
    if not settings.pause_during_goals:
        return None
    return GoalActivity(node, settings.manipulate_action, settings.goal_pause_limit_s, on_change)
