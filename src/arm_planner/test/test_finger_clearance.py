import numpy as np
import pytest
import trimesh

from arm_planner.finger_clearance import OpenFingers, clear_closing_axis, clearance_m, finger_points, halfspaces
from arm_planner.tasks.base import TargetGeometry
from arm_planner.tasks.grasp import GraspReward

FINGERS = OpenFingers(gap_m=0.08, thickness_m=0.012, width_m=0.02, length_m=0.055, tcp_above_tip_m=0.007)
GRASP = np.array([0.0, 0.0, 0.03])


def _block(centre, size=(0.04, 0.04, 0.10)) -> np.ndarray:
    box = trimesh.creation.box(size)
    box.apply_translation(centre)
    return halfspaces(box)


def test_finger_points_fill_both_open_fingers_from_the_tips_up():
    points = finger_points(GRASP, np.array([1.0, 0.0]), FINGERS)
    inner = 0.5 * FINGERS.gap_m
    assert np.all(np.abs(points[:, 0]) >= inner - 1e-12)
    assert np.all(np.abs(points[:, 0]) <= inner + FINGERS.thickness_m + 1e-12)
    assert np.all(np.abs(points[:, 1]) <= 0.5 * FINGERS.width_m + 1e-12)
    tip = GRASP[2] - FINGERS.tcp_above_tip_m
    assert points[:, 2].min() == pytest.approx(tip) and points[:, 2].max() == pytest.approx(tip + FINGERS.length_m)
    assert (points[:, 0] > 0).sum() == (points[:, 0] < 0).sum()


def test_clearance_is_the_gap_outside_and_minus_the_depth_inside():
    planes = _block((0.1, 0.0, 0.05))  # faces at x = 0.08 and 0.12
    assert clearance_m(np.array([[0.05, 0.0, 0.05]]), [planes]) == pytest.approx(0.03)
    assert clearance_m(np.array([[0.09, 0.0, 0.05]]), [planes]) == pytest.approx(-0.01)
    assert clearance_m(np.array([[0.05, 0.0, 0.05]]), []) == np.inf


def test_a_clear_preferred_axis_is_kept_bit_for_bit():
    planes = [_block((0.0, 0.2, 0.05))]  # well beyond the fingers
    preferred = np.array([np.cos(0.3), np.sin(0.3), 0.0])
    np.testing.assert_array_equal(clear_closing_axis(GRASP, preferred, FINGERS, planes), preferred)


def test_a_finger_on_a_neighbour_turns_the_axis_as_little_as_it_takes():
    planes = [_block((0.065, 0.0, 0.05))]  # the +x finger would come down on it
    axis = clear_closing_axis(GRASP, [1.0, 0.0], FINGERS, planes)
    assert axis[2] == 0.0 and np.linalg.norm(axis) == pytest.approx(1.0)
    assert clearance_m(finger_points(GRASP, axis[:2], FINGERS), planes) >= 0.01
    turn = np.degrees(np.arccos(abs(axis[0])))
    assert 0 < turn < 90, "not simply the perpendicular: the smallest turn that clears"
    for smaller in np.arange(15.0, turn, 15.0):
        a = np.radians(smaller)
        for sign in (1, -1):
            probe = np.array([np.cos(a), sign * np.sin(a)])
            assert clearance_m(finger_points(GRASP, probe, FINGERS), planes) < 0.01


def test_axes_the_object_does_not_fit_along_are_never_chosen():
    planes = [_block((0.065, 0.0, 0.05))]
    axis = clear_closing_axis(GRASP, [1.0, 0.0], FINGERS, planes, fits=lambda a: abs(a[1]) > 0.99)
    np.testing.assert_allclose(np.abs(axis), [0.0, 1.0, 0.0], atol=1e-9)


def test_a_rearrange_closes_across_the_carry_when_a_finger_would_land_on_a_neighbour():
    cube = np.array([[x, y, z] for x in (-0.02, 0.02) for y in (-0.02, 0.02) for z in (0.0, 0.06)])
    neighbour = _block((0.065, 0.0, 0.05))
    geometry = TargetGeometry(np.array([0.0, 0.0, 0.03]), cube, 0.0, obstacle_halfspaces=[neighbour])
    options = dict(
        hand=None, target=None, qpos_offset=0, nq=0, goal_displacement=np.array([0.2, 0.0, 0.0]), carry_height_m=0.04
    )
    along = GraspReward(geometry=geometry, finger_gap_open_m=FINGERS.gap_m, **options)
    np.testing.assert_allclose(np.abs(along.closing_axis), [1.0, 0.0, 0.0], err_msg="no finger sizes: along the carry")
    cleared = GraspReward(geometry=geometry, finger_gap_open_m=FINGERS.gap_m, fingers=FINGERS, **options)
    assert abs(cleared.closing_axis[0]) < 0.99
    assert clearance_m(finger_points(cleared.grasp_point, cleared.closing_axis[:2], FINGERS), [neighbour]) >= 0.005
