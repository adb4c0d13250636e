import numpy as np
import pytest
from task_kinematics import poses_from

from arm_planner.tasks.base import TargetGeometry, tilt_beyond
from arm_planner.tasks.grasp import GraspReward


def _box_grasp() -> GraspReward:
    """A grasp of a 4 x 4 x 8 cm box; hand position in qpos[0:3], box centre in qpos[3:6]."""
    box = np.array([[x, y, z] for x in (-0.02, 0.02) for y in (-0.02, 0.02) for z in (0.0, 0.08)])
    geometry = TargetGeometry(np.array([0.0, 0.0, 0.04]), box, 0.0)
    return GraspReward(hand=poses_from(0), target=poses_from(3), geometry=geometry, qpos_offset=0, nq=6)


def test_the_hand_holds_still_while_the_fingers_close_on_a_nudged_object():
    reward = _box_grasp()
    geometry = reward.geometry
    at_rest = np.concatenate([reward.grasp_point, geometry.com_world])
    while reward.state == "ungrasped":
        reward.update(at_rest)
        assert reward.step_count < 50
    nudged = geometry.com_world + [0.03, 0.0, 0.0]
    holding = np.concatenate([reward.grasp_point, nudged])
    chasing = np.concatenate([nudged + reward.grasp_offset, nudged])
    scores = reward(np.stack([holding, chasing]), np.zeros((2, 0)))
    assert scores[0] > scores[1], "closing, the hand stays where the fingers began to close"
    for _ in range(reward.close_steps):
        reward.update(holding)
    assert reward.state == "grasped"
    scores = reward(np.stack([holding, chasing]), np.zeros((2, 0)))
    assert scores[1] > scores[0], "grasped, the hand goes with the object again"


def test_fingers_closing_short_of_the_site_hold_the_site_not_the_hand():
    reward = _box_grasp()
    geometry = reward.geometry
    above = reward.grasp_point + [0.0, 0.0, 0.008]  # within close_distance_m, still coming down
    arriving = np.concatenate([above, geometry.com_world])
    while reward.state == "ungrasped":
        reward.update(arriving)
        assert reward.step_count < 50
    at_site = np.concatenate([reward.grasp_point, geometry.com_world])
    scores = reward(np.stack([at_site, arriving]), np.zeros((2, 0)))
    assert scores[0] > scores[1], "closing, the hand goes on to the site rather than staying short of it"


def _grasp_on(com_z: float, top_z: float) -> GraspReward:
    box = np.array([[x, y, z] for x in (-0.02, 0.02) for y in (-0.02, 0.02) for z in (0.0, top_z)])
    geometry = TargetGeometry(np.array([0.0, 0.0, com_z]), box, 0.0)
    return GraspReward(hand=None, target=None, geometry=geometry, qpos_offset=0, nq=0)


def test_grasp_height_is_the_centre_of_mass_within_the_fingers_reach():
    reward = _grasp_on(com_z=0.04, top_z=0.064)
    assert reward.grasp_point[2] == pytest.approx(0.04), "at the centre of mass: no gravity torque in the grip"
    tall = _grasp_on(com_z=0.10, top_z=0.20)
    assert tall.grasp_point[2] == pytest.approx(0.20 - tall.grasp_max_depth_m), "the palm stops at the top"
    top_heavy = _grasp_on(com_z=0.06, top_z=0.064)
    assert top_heavy.grasp_point[2] == pytest.approx(0.064 - top_heavy.grasp_min_depth_m), "fingers overlap it"
    flat = _grasp_on(com_z=0.01, top_z=0.02)
    assert flat.grasp_point[2] == pytest.approx(0.015), "fingertips clear of the table"


REARRANGE = np.array([0.20, 0.20, 0.0])
_CUBE = np.array([[x, y, z] for x in (-0.02, 0.02) for y in (-0.02, 0.02) for z in (0.0, 0.06)])


def _rearrange(obstacles=None, box=_CUBE, goal_displacement=REARRANGE, **options) -> GraspReward:
    obstacles = np.zeros((0, 3)) if obstacles is None else obstacles
    geometry = TargetGeometry(np.array([0.0, 0.0, 0.03]), box, 0.0, obstacle_vertices_world=obstacles)
    return GraspReward(
        hand=None,
        target=None,
        geometry=geometry,
        qpos_offset=0,
        nq=0,
        goal_displacement=goal_displacement,
        carry_height_m=0.04,
        **options,
    )


def _column(x, y, height_m):
    return np.array([[x + dx, y + dy, z] for dx in (-0.01, 0.01) for dy in (-0.01, 0.01) for z in (0.0, height_m)])


def test_rearrange_carries_over_the_objects_on_its_way_and_no_higher_than_the_cap():
    assert _rearrange().carry_height_m == pytest.approx(0.04), "nothing on the way: the configured height"
    assert _rearrange(_column(0.1, 0.1, 0.03)).carry_height_m == pytest.approx(0.045), "clears a low object"
    assert _rearrange(_column(0.1, 0.1, 0.07)).carry_height_m == pytest.approx(0.085)
    assert _rearrange(_column(0.1, 0.1, 0.30)).carry_height_m == pytest.approx(0.10), "capped"
    assert _rearrange(_column(0.2, -0.1, 0.30)).carry_height_m == pytest.approx(0.04), "off the path"


def test_rearrange_lifts_straight_up_then_carries_then_places_straight_down():
    reward = _rearrange()
    reward.resume("grasped", 0)
    where = {"target": reward.start_com.copy()}
    reward.poses = lambda states: (where["target"][None], None, where["target"][None], None)
    up = np.array([0.0, 0.0, reward.carry_height_m])

    def step_to(position):
        where["target"] = np.asarray(position, dtype=np.float64)
        reward.update(np.zeros(1))
        return reward.carry_goal(where["target"][None])[0]

    np.testing.assert_allclose(step_to(reward.start_com + [0.02, 0.0, 0.0]), reward.start_com + up)
    np.testing.assert_allclose(step_to(reward.start_com + [0.0, 0.0, 0.035]), reward.goal + up, err_msg="raised: carry")
    np.testing.assert_allclose(step_to(reward.start_com + [0.1, 0.1, 0.01]), reward.goal + up, err_msg="carry stays up")
    np.testing.assert_allclose(step_to(reward.goal + [0.015, 0.0, 0.04]), reward.goal, err_msg="above the goal: place")
    np.testing.assert_allclose(step_to(reward.goal + [0.03, 0.0, 0.02]), reward.goal, err_msg="placing stays placing")


def test_rearrange_that_cannot_lift_is_carried_after_the_timeout():
    reward = _rearrange()
    reward.resume("grasped", 0)
    reward.poses = lambda states: (reward.start_com[None], None, reward.start_com[None], None)
    for _ in range(reward.lift_timeout_steps):
        reward.update(np.zeros(1))
    assert reward.carry_phase == "carry"


def test_a_grasp_has_no_carry_phases():
    geometry = TargetGeometry(np.array([0.0, 0.0, 0.03]), _CUBE, 0.0)
    reward = GraspReward(hand=None, target=None, geometry=geometry, qpos_offset=0, nq=0)
    reward.resume("grasped", 0)
    np.testing.assert_allclose(reward.carry_goal(reward.start_com[None])[0], reward.goal)


def _hand_tilted(degrees: float) -> np.ndarray:
    """A hand pointing down (approach axis world -z), then tilted about world x."""
    a = np.radians(degrees)
    tilt = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(a), -np.sin(a)], [0.0, np.sin(a), np.cos(a)]])
    return tilt @ np.diag([1.0, -1.0, -1.0])


def test_carry_tilt_costs_nothing_within_the_free_band_and_grows_linearly_beyond():
    free = np.radians(30.0)
    assert tilt_beyond(_hand_tilted(0.0), free) == pytest.approx(0.0, abs=1e-9)
    assert tilt_beyond(_hand_tilted(25.0), free) == pytest.approx(0.0, abs=1e-9)
    assert tilt_beyond(_hand_tilted(60.0), free) == pytest.approx(np.radians(30.0))
    assert tilt_beyond(_hand_tilted(90.0), free) == pytest.approx(np.radians(60.0))


def test_rearrange_replanned_mid_carry_carries_on_at_the_height_from_its_start():
    start = np.array([0.0, 0.0, 0.03])
    obstacle = _column(0.15, 0.15, 0.07)
    first = _rearrange(obstacle)
    # Re-planned with the object held 8.5 cm up and 5 cm along the way: the task's start and goal stay.
    now = np.array([0.05, 0.05, 0.085])
    geometry = TargetGeometry(start + now, _CUBE + now, 0.0, obstacle_vertices_world=obstacle)
    reward = GraspReward(
        hand=None, target=None, geometry=geometry, qpos_offset=0, nq=0, goal_displacement=REARRANGE, carry_height_m=0.04
    )
    reward.start_com, reward.goal = start.copy(), start + REARRANGE
    reward.resume("grasped", 30)
    assert reward.carry_height_m == pytest.approx(first.carry_height_m), "measured from the base at the start"
    assert reward.carry_phase == "carry"
    np.testing.assert_allclose(reward.carry_goal(now[None])[0], reward.goal + [0.0, 0.0, first.carry_height_m])
    # Re-planned while still lifting, in place: it goes on lifting.
    lifting = _rearrange(obstacle)
    lifting.resume("grasped", 5)
    assert lifting.carry_phase == "lift"


def _carrying():
    """(a rearrange carrying its object, states_at, a target point at the carry height): states_at(target)
    gives the state [simulated hand, target] and the commanded hand at the simulated one (hand down)."""
    reward = _rearrange()
    reward.resume("grasped", 0)
    reward.carry_phase = "carry"
    reward.hand, reward.target, reward.nq = poses_from(0), poses_from(3), 6
    reward.arm_qpos_adr, reward.arm_actuators = np.arange(3), np.arange(3)

    def states_at(target):
        hand = np.asarray(target, dtype=np.float64) + reward.grasp_offset
        return np.concatenate([hand, target]), hand

    return reward, states_at, reward.start_com + [0.02, 0.02, reward.carry_height_m]


def test_carrying_the_object_below_the_carry_height_costs_more_than_its_distance_to_the_goal():
    reward, states_at, level = _carrying()
    sagged = level - [0.0, 0.0, 0.03]
    (a, ca), (b, cb) = states_at(level), states_at(sagged)
    scores = reward(np.stack([a, b]), np.stack([ca, cb]))
    distance_gap = np.linalg.norm(reward.carry_goal(sagged) - sagged) - np.linalg.norm(reward.carry_goal(level) - level)
    assert distance_gap < 0.005, "far from the goal, sinking 3 cm hardly changes the distance"
    assert scores[0] - scores[1] > 0.1, "but the carry height holds it up"


def test_held_object_is_not_pulled_down_by_the_commanded_hand_sitting_above_it():
    reward, states_at, level = _carrying()
    state, hand = states_at(level)
    # The servos lag by the whole horizon: the simulated hand is where it is whatever the command. A
    # command 4 mm above it (the arm's sag under the load) holds the height; one at it lowers the arm.
    holding, lowering = hand + [0.0, 0.0, 0.004], hand
    scores = reward(np.stack([state, state]), np.stack([holding, lowering]))
    assert scores[0] >= scores[1] - 1e-12


def test_rearrange_fingers_close_along_the_carry_when_the_object_fits():
    def closing(extents, gap=0.082):
        box = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (0.0, 0.06)]) * [*extents, 1.0] / 2
        return _rearrange(box=box, goal_displacement=np.array([0.2, 0.0, 0.0]), finger_gap_open_m=gap).closing_axis

    np.testing.assert_allclose(np.abs(closing((0.04, 0.03))), [1.0, 0.0, 0.0], atol=1e-9, err_msg="fits: along")
    np.testing.assert_allclose(np.abs(closing((0.07, 0.03))), [0.0, 1.0, 0.0], atol=1e-9, err_msg="too long")
    np.testing.assert_allclose(np.abs(closing((0.04, 0.03), gap=0.0)), [0.0, 1.0, 0.0], atol=1e-9, err_msg="no gap")


def test_narrowest_horizontal_width_is_the_short_side_of_a_box_whatever_its_yaw():
    from arm_planner.tasks.base import narrowest_horizontal_width_m

    corners = np.array([[x, y, z] for x in (-0.1, 0.1) for y in (-0.03, 0.03) for z in (0.0, 0.2)])
    for yaw in (0.0, np.pi / 12, np.pi / 3):
        c, s = np.cos(yaw), np.sin(yaw)
        rotated = corners @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T
        assert narrowest_horizontal_width_m(rotated + [0.4, -0.2, 0.7]) == pytest.approx(0.06, abs=1e-9)
