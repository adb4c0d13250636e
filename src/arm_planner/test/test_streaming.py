"""TrajectoryStream: parts of a plan being planned join into the plan, whether the controller keeps up
or waits for the planner."""

import numpy as np
import pytest

from arm_planner.streaming import TrajectoryStream

DT = 0.02


def _plan(n):
    return np.stack([np.linspace(0.0, 1.0, n), np.linspace(1.0, 0.0, n)], axis=1)


def _stream(plan, plan_s_per_step, lead_s=0.1, period_s=0.06):
    """Feed the plan at `plan_s_per_step` wall seconds per planned step; the parts with their send times."""
    stream = TrajectoryStream(DT, lead_s, period_s)
    parts = []
    for i, q in enumerate(plan):
        stream.add(q)
        if stream.due():
            now = (i + 1) * plan_s_per_step
            parts.append((now, stream.part(now)))
    now = len(plan) * plan_s_per_step
    final = stream.part(now)
    if final is not None:
        parts.append((now, final))
    return stream, parts


def _executed(parts):
    """Waypoints a replacing controller reaches: each part up to the next one's send time; with the
    absolute time each is reached."""
    points, times = [], []
    for k, (sent, part) in enumerate(parts):
        until = parts[k + 1][0] if k + 1 < len(parts) else np.inf
        reach = sent + part.times_s
        keep = reach <= until + 1e-9
        points.extend(part.positions[keep])
        times.extend(reach[keep])
    return np.array(points), np.array(times)


@pytest.mark.parametrize("speed", [0.25, 0.5, 1.0])
def test_parts_join_into_the_plan_when_planning_keeps_up(speed):
    plan = _plan(60)
    stream, parts = _stream(plan, speed * DT)
    assert len(parts) > 3 and stream.stall_s == pytest.approx(0.0)
    assert np.allclose(parts[0][1].positions, plan[: len(parts[0][1].positions)])
    assert len(parts[0][1].positions) == 5  # lead 0.1 s
    points, times = _executed(parts)
    assert np.allclose(points, plan)  # every point once, in order
    assert np.allclose(np.diff(times), DT)  # at the plan's pace, no gap
    assert times[0] == pytest.approx(parts[0][0] + DT)


def test_a_slow_planner_makes_the_controller_wait_without_skipping():
    plan = _plan(40)
    stream, parts = _stream(plan, 2.0 * DT)  # planning takes twice the motion
    points, times = _executed(parts)
    assert np.allclose(points, plan)
    assert np.all(np.diff(times) >= DT - 1e-9)
    assert stream.stall_s > 0.3
    assert parts[-1][1].times_s[-1] == pytest.approx(DT * 40 - stream.executed_s)


def test_nothing_new_no_part_and_bad_settings():
    stream = TrajectoryStream(DT, 0.0, 0.0)
    assert not stream.due() and stream.part(0.0) is None
    stream.add([1.0])
    assert stream.due()
    assert stream.part(0.0).positions.shape == (1, 1)
    assert stream.part(0.01) is None and not stream.due()
    with pytest.raises(ValueError):
        TrajectoryStream(0.0, 0.1, 0.1)
