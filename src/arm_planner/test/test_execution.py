"""A plan split for a ros2_control robot: the arm's trajectory, and gripper set points when they are due."""

import numpy as np
import pytest

from arm_planner.execution import split_plan

NAMES = ["j1", "j2", "finger"]


def _plan(fingers):
    times = 0.02 * np.arange(1, len(fingers) + 1)
    positions = np.column_stack([np.linspace(0, 1, len(fingers)), np.linspace(1, 0, len(fingers)), fingers])
    return times, positions


def test_the_arm_keeps_every_point_and_each_finger_change_is_one_set_point_due_when_it_starts():
    times, positions = _plan([0.04, 0.04, 0.0, 0.0, 0.0, 0.04])
    commands = split_plan(NAMES, times, positions, "finger", gripper_now_m=None)
    assert commands.arm_joint_names == ("j1", "j2")
    assert np.array_equal(commands.arm_positions, positions[:, :2]) and np.array_equal(commands.times_s, times)
    assert [(round(g.due_s, 3), g.position_m) for g in commands.gripper] == [(0.0, 0.04), (0.04, 0.0), (0.1, 0.04)]


def test_a_plan_starting_where_the_gripper_is_sends_no_set_point_at_its_start():
    times, positions = _plan([0.04, 0.04, 0.04])
    assert split_plan(NAMES, times, positions, "finger", gripper_now_m=0.04).gripper == ()
    assert len(split_plan(NAMES, times, positions, "finger", gripper_now_m=0.0).gripper) == 1


def test_a_plan_without_the_finger_is_refused():
    times, positions = _plan([0.04])
    with pytest.raises(ValueError, match="finger"):
        split_plan(["a", "b", "c"], times, positions, "finger", None)
