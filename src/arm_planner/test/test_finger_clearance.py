import numpy as np
import pytest
import trimesh

from arm_planner.finger_clearance import (
    DepthGrid,
    OpenFingers,
    clear_closing_axis,
    clearance_m,
    deepest_finger_m,
    finger_points,
    finger_points_in_hand,
    halfspaces,
    palm_points,
)
from arm_planner.grasp_site import Occupancy
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


def test_finger_points_in_hand_hang_from_the_tcp_along_the_approach_axis():
    points = finger_points_in_hand(FINGERS)
    assert points[:, 2].max() == pytest.approx(FINGERS.tcp_above_tip_m), "the tips lie beyond the TCP"
    assert points[:, 2].min() == pytest.approx(FINGERS.tcp_above_tip_m - FINGERS.length_m)
    assert np.all(np.abs(points[:, 1]) >= 0.5 * FINGERS.gap_m - 1e-12), "the fingers close along hand y"
    assert np.all(np.abs(points[:, 0]) <= 0.5 * FINGERS.width_m + 1e-12)


def _tall_block_depth(voxel_m=0.004) -> DepthGrid:
    planes = [_block((0.0, 0.0, 0.10), size=(0.04, 0.04, 0.20))]
    lo, hi = np.array([-0.03, -0.03, -0.01]), np.array([0.03, 0.03, 0.21])
    occupancy = Occupancy.from_parts(planes, lo, hi, voxel_m)
    return DepthGrid.from_filled(occupancy.origin_world, voxel_m, occupancy.filled)


def test_depth_grid_is_zero_outside_and_grows_down_from_the_top():
    grid = _tall_block_depth()  # a 20 cm block: its top at 0.2 m
    depth = grid.depth_at(np.array([[0.05, 0.0, 0.1], [0.0, 0.0, 0.25], [0.013, 0.0, 0.19], [0.0, 0.0, 0.1]]))
    assert depth[0] == 0.0 and depth[1] == 0.0
    assert 0.0 < depth[2] < depth[3]
    assert depth[2] == pytest.approx(0.01, abs=0.004) and depth[3] == pytest.approx(0.1, abs=0.004)


def test_a_finger_coming_down_on_a_tall_object_is_deep_in_it_and_one_beside_it_is_not():
    grid = _tall_block_depth()
    down = np.diag([1.0, -1.0, -1.0])  # hand z along world -z, closing along world y
    points = finger_points_in_hand(FINGERS, spacing_m=0.015)
    hands = np.array([[0.0, 0.0, 0.17], [0.0, 0.03, 0.17]])  # centred over it / 3 cm off along the closing axis
    depth = deepest_finger_m(hands, np.broadcast_to(down, (2, 3, 3)), points, grid)
    assert depth[0] == 0.0
    assert depth[1] > 0.005


def _thin_walled_cup(wall_m=0.004, radius_m=0.03, height_m=0.08) -> Occupancy:
    parts = [trimesh.creation.box((2 * radius_m, 2 * radius_m, wall_m)).apply_translation((0, 0, wall_m / 2))]
    for k in range(12):
        slab = trimesh.creation.box((wall_m, 0.017, height_m)).apply_translation(
            (radius_m - wall_m / 2, 0, height_m / 2)
        )
        parts.append(slab.apply_transform(trimesh.transformations.rotation_matrix(np.pi * k / 6, (0, 0, 1))))
    lo, hi = np.array([-0.04, -0.04, -0.004]), np.array([0.04, 0.04, height_m + 0.004])
    return Occupancy.from_parts([halfspaces(p) for p in parts], lo, hi, 0.004)


def test_a_finger_pushed_down_into_a_thin_rim_is_as_deep_as_it_pushed():
    cup = _thin_walled_cup()
    down = np.broadcast_to(np.diag([1.0, -1.0, -1.0]), (4, 3, 3))
    points = finger_points_in_hand(FINGERS, spacing_m=0.015)
    # centred (fingers outside), a finger tip 1.7 cm down into the rim, one in the open mouth, one beside
    hands = np.array([[0.0, 0.0, 0.03], [0.0, 0.02, 0.07], [0.0, 0.035, 0.07], [0.0, 0.075, 0.05]])
    depth = deepest_finger_m(hands, down, points, DepthGrid.from_filled(cup.origin_world, 0.004, cup.filled))
    assert depth[1] == pytest.approx(0.018, abs=0.004), "not the 2 mm to the wall's nearest surface"
    assert depth[0] == depth[2] == depth[3] == 0.0


def test_a_tall_neighbour_under_the_palm_turns_the_axis_too():
    with_palm = OpenFingers(**(FINGERS.__dict__ | {"palm_length_m": 0.2, "palm_width_m": 0.04}))
    tall = [_block((0.085, 0.0, 0.10), size=(0.02, 0.02, 0.20))]  # beyond the +x finger, under the palm
    assert clearance_m(finger_points(GRASP, np.array([1.0, 0.0]), FINGERS), tall) > 0.01, "the fingers clear it"
    np.testing.assert_array_equal(clear_closing_axis(GRASP, [1.0, 0.0], FINGERS, tall), [1.0, 0.0, 0.0])
    axis = clear_closing_axis(GRASP, [1.0, 0.0], with_palm, tall)
    assert abs(axis[0]) < 0.99, "the palm would come down on it: turned"
    assert clearance_m(palm_points(GRASP, axis[:2], with_palm), tall) >= 0.0
    assert len(palm_points(GRASP, axis[:2], FINGERS)) == 0, "no palm size: not checked"
