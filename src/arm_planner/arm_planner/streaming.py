"""Receding-horizon execution (MJPC style): the controller executes the planned prefix while MPPI plans on.

The planner emits one control (joint targets) per control step. TrajectoryStream collects them and
says when to send the controller a part: first once `lead_s` of motion is planned, then whenever
`period_s` more is. The controller replaces its trajectory with every message and interpolates from
its current command to the first point (ROS JointTrajectory semantics), so each part holds every
planned point not executed yet, times counted from the moment it is sent (its header stamp: a
controller that keeps to the stamp continues the plan when a part arrives late). The stream books
how far the controller got: the time since the previous part, capped at that part's end (after its
end the controller holds the last point until the next part comes, then continues from there).
Pure: no rclpy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class StreamPart:
    times_s: np.ndarray  # from the moment the part is sent, s
    positions: np.ndarray  # [n, joints]
    plan_start_s: float  # plan time the part starts after (executed so far), s


class TrajectoryStream:
    def __init__(self, control_dt_s: float, lead_s: float, period_s: float):
        if control_dt_s <= 0 or lead_s < 0 or period_s < 0:
            raise ValueError(f"control_dt_s {control_dt_s} must be > 0, lead_s {lead_s} and period_s {period_s} >= 0")
        self.control_dt_s = float(control_dt_s)
        self.lead_s = float(lead_s)
        self.period_s = float(period_s)
        self.positions: list[np.ndarray] = []
        self.executed_s = 0.0  # plan time the controller has reached
        self.sent_end_s = 0.0  # plan time of the last point sent
        self.sent_at_s: float | None = None  # clock time of the last part
        self.parts = 0
        self.stall_s = 0.0  # time the controller held still waiting for a part, s

    @property
    def planned_s(self) -> float:
        return self.control_dt_s * len(self.positions)

    def add(self, position) -> None:
        self.positions.append(np.asarray(position, dtype=np.float64).copy())

    def due(self) -> bool:
        if self.sent_at_s is None:
            return self.planned_s >= self.lead_s - 1e-9 and len(self.positions) > 0
        return self.planned_s - self.sent_end_s >= max(self.period_s, self.control_dt_s / 2) - 1e-9

    def part(self, now_s: float) -> StreamPart | None:
        """The part to send at clock time `now_s` (every planned point not executed yet); None when
        nothing new was planned since the last part."""
        if self.sent_at_s is not None:
            elapsed = max(0.0, now_s - self.sent_at_s)
            reached = min(self.executed_s + elapsed, self.sent_end_s)
            self.stall_s += max(0.0, self.executed_s + elapsed - self.sent_end_s)
            self.executed_s = reached
        if self.planned_s <= self.sent_end_s + 1e-9:
            return None
        times = self.control_dt_s * np.arange(1, len(self.positions) + 1)
        first = int(np.searchsorted(times, self.executed_s + 1e-9, side="right"))
        self.sent_at_s, self.sent_end_s = now_s, float(times[-1])
        self.parts += 1
        return StreamPart(times[first:] - self.executed_s, np.array(self.positions[first:]), self.executed_s)
