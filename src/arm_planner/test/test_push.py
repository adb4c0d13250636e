import numpy as np
import pytest
import trimesh
from task_kinematics import poses_from

from arm_planner.tasks.base import RewardWeights, TargetGeometry
from arm_planner.tasks.push import CagePushReward, PushReward
from arm_reconstruction.metrics import sample_surface_points

GOAL = np.array([0.05, -0.30, 0.0])


def _push(target_vel_adr=None) -> PushReward:
    box = np.array([[x, y, z] for x in (-0.02, 0.02) for y in (-0.02, 0.02) for z in (0.0, 0.06)])
    geometry = TargetGeometry(np.array([0.0, 0.0, 0.03]), box, 0.0)
    return PushReward(
        hand=None,
        target=None,
        geometry=geometry,
        qpos_offset=0,
        nq=0,
        weights=RewardWeights(),
        goal_displacement=GOAL,
        target_vel_adr=target_vel_adr,
    )


def test_rest_point_adds_the_sliding_distance_of_the_objects_velocity():
    reward = _push(target_vel_adr=0)
    states = np.array([[0.5, 0.0, 0.0], [0.0, 0.0, 0.0]])
    rest, speed = reward.rest_xy(states, np.zeros((2, 3)))
    np.testing.assert_allclose(rest[0], [0.25 / (2 * reward.friction * 9.81), 0.0])
    np.testing.assert_allclose(rest[1], [0.0, 0.0])
    np.testing.assert_allclose(speed, [0.5, 0.0])
    still, _ = _push().rest_xy(states, np.zeros((2, 3)))
    np.testing.assert_allclose(still, 0.0)


def test_a_push_resumed_while_pushing_counts_as_near_the_object_from_its_first_step():
    reward = _push()
    assert not reward.near_contact
    reward.resume("pushing", 12)
    assert reward.near_contact
    reward.resume("approaching", 0)
    assert not reward.near_contact


def test_push_direction_does_not_swing_round_at_or_just_past_the_goal():
    reward = _push()
    nominal = GOAL[:2] / np.linalg.norm(GOAL[:2])
    positions = np.array([[0.0, 0.0, 0.03], reward.goal, reward.goal + [0.01, -0.02, 0.0]])
    directions = reward._direction(positions)
    assert np.all(directions @ nominal > 0.8)
    sideways = reward._direction(np.array([[0.05, 0.0, 0.03]]))[0]
    assert nominal[0] * sideways[1] - nominal[1] * sideways[0] < 0, "a sideways drift is steered back"


def test_push_contact_point_turns_with_the_object():
    long_box = np.array([[x, y, z] for x in (-0.08, 0.08) for y in (-0.01, 0.01) for z in (0.0, 0.06)])
    geometry = TargetGeometry(np.array([0.0, 0.0, 0.03]), long_box, 0.0)
    reward = PushReward(
        hand=None, target=None, geometry=geometry, qpos_offset=0, nq=0, goal_displacement=np.array([0.3, 0.0, 0.0])
    )
    centre = geometry.com_world[None]
    quarter_turn = np.array([[[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]])
    as_built = reward._contact_point(centre, np.eye(3)[None], gap_m=0.0)[0]
    turned = reward._contact_point(centre, quarter_turn, gap_m=0.0)[0]
    np.testing.assert_allclose(as_built[:2], [-0.08, 0.0], atol=1e-9)
    np.testing.assert_allclose(turned[:2], [-0.01, 0.0], atol=1e-9)


def test_push_contact_point_is_where_the_leaning_finger_first_meets_the_object():
    """A T standing on its stem: the fingertip goes to the stem, not into the air under the bar's
    overhang; a part of the object high up meets the leaning finger later than one at its base."""
    stem = [[x, y, z] for x in (-0.01, 0.01) for y in (-0.02, 0.02) for z in (0.0, 0.05)]
    bar = [[x, y, z] for x in (-0.05, 0.05) for y in (-0.02, 0.02) for z in (0.05, 0.07)]
    geometry = TargetGeometry(np.array([0.0, 0.0, 0.04]), np.array(stem + bar), 0.0)
    reward = PushReward(
        hand=None, target=None, geometry=geometry, qpos_offset=0, nq=0, goal_displacement=np.array([0.3, 0.0, 0.0])
    )
    contact = reward._contact_point(geometry.com_world[None], np.eye(3)[None], gap_m=0.0)[0]
    setback = (0.05 - reward.push_z) * np.tan(reward.tilt_rad)
    assert contact[0] < -0.01 - 1e-9, "no closer than the stem"
    np.testing.assert_allclose(contact[0], -max(0.01, 0.05 - setback), atol=1e-9)


def _cage_on(extents, com_z=None) -> CagePushReward:
    x, y, z = extents
    box = np.array([[i, j, k] for i in (-x / 2, x / 2) for j in (-y / 2, y / 2) for k in (0.0, z)])
    geometry = TargetGeometry(np.array([0.0, 0.0, z / 2 if com_z is None else com_z]), box, 0.0)
    return CagePushReward(
        hand=poses_from(0),
        target=poses_from(3),
        geometry=geometry,
        qpos_offset=0,
        nq=6,
        goal_displacement=np.array([0.3, 0.0, 0.0]),
    )


def test_only_objects_that_fit_between_the_open_fingers_are_caged():
    def fits(extents):
        reward = _cage_on(extents)
        return CagePushReward.fits_cage(reward.geometry, reward.goal_displacement, 0.082, 0.055)

    assert fits((0.05, 0.12, 0.064)), "long across the push is fine: the fingers are fore and aft"
    assert not fits((0.07, 0.03, 0.064)), "too long along the push for the open fingers and their margins"
    assert not fits((0.04, 0.04, 0.12)), "the palm would meet the top with the fingertips this high"
    geometry = _cage_on((0.04, 0.04, 0.06)).geometry
    assert not CagePushReward.fits_cage(geometry, np.array([0.3, 0.0, 0.0]), 0.0, 0.0), "no finger geometry"


def test_cage_comes_down_over_the_object_then_leads_with_the_rear_finger_pressing():
    low = _cage_on((0.04, 0.03, 0.04))
    tip_z = low.cage_offset[2] + low.geometry.com_world[2] - low.tcp_above_fingertip_m
    assert tip_z == pytest.approx(low.tip_clearance_m), "fingertips just above the table"
    tall = _cage_on((0.04, 0.03, 0.064))
    tall_tip_z = tall.cage_offset[2] + tall.geometry.com_world[2] - tall.tcp_above_fingertip_m
    assert tall_tip_z == pytest.approx(0.064 + tall.palm_clearance_m - tall.finger_length_m), "palm clears the top"
    com = low.geometry.com_world
    cage = com + low.cage_offset
    beside = np.concatenate([cage + [-0.04, 0.0, 0.0], com])  # a finger width behind, at the cage's height
    above = np.concatenate([cage + [-0.04, 0.0, 0.06], com])
    scores = low(np.stack([beside, above]), np.zeros((2, 0)))
    assert scores[1] > scores[0], "approaching, the fingertips stay above the top until over the object"
    low.update(np.concatenate([cage, com]))
    assert low.state == "pushing" and low.near_contact
    centred = np.concatenate([cage, com])
    leading = np.concatenate([cage + [low.cage_margin_m + low.press_m, 0.0, 0.0], com])
    scores = low(np.stack([centred, leading]), np.zeros((2, 0)))
    assert scores[1] > scores[0], "pushing, the hand leads so the rear finger presses on the object"


def test_one_finger_backs_off_an_object_that_slid_past_the_goal_instead_of_pushing_it_further():
    box = np.array([[i, j, k] for i in (-0.02, 0.02) for j in (-0.02, 0.02) for k in (0.0, 0.06)])
    geometry = TargetGeometry(np.array([0.0, 0.0, 0.03]), box, 0.0)
    reward = PushReward(
        hand=poses_from(0), target=poses_from(3), geometry=geometry, qpos_offset=0, nq=6,
        goal_displacement=np.array([0.3, 0.0, 0.0]),
    )  # fmt: skip
    reward.resume("pushing", 0)

    def pressing_beats_backing_off(object_x_m: float) -> bool:
        at = reward.goal + [object_x_m - reward.goal[0], 0.03, 0.0]  # 3 cm to the side, short of or past
        press = reward._contact_point(at[None], np.eye(3)[None], reward.push_gap_m)[0]
        back = reward._contact_point(at[None], np.eye(3)[None], reward.retreat_gap_m)[0]
        scores = reward(np.stack([np.concatenate([press, at]), np.concatenate([back, at])]), np.zeros((2, 0)))
        return bool(scores[0] > scores[1])

    assert pressing_beats_backing_off(reward.goal[0] - 0.05), "short of the goal, the finger pushes"
    assert not pressing_beats_backing_off(reward.goal[0] + 0.01), "past it, pushing only takes it further"


def test_cage_pushes_an_object_that_slid_past_the_goal_back_with_the_front_finger():
    reward = _cage_on((0.04, 0.03, 0.04))
    reward.resume("pushing", 0)
    past = reward.goal + [0.03, 0.0, 0.0]
    cage = past + reward.cage_offset
    lead = reward.cage_margin_m + reward.press_m
    forward = np.concatenate([cage + [lead, 0.0, 0.0], past])
    back = np.concatenate([cage - [lead, 0.0, 0.0], past])
    scores = reward(np.stack([forward, back]), np.zeros((2, 0)))
    assert scores[1] > scores[0], "past the goal, the hand leads back towards it"


@pytest.mark.parametrize("margin_m", [0.003, 0.0, -0.002])
def test_cage_fingers_open_to_approach_and_close_to_the_object_plus_margins_to_push(margin_m):
    reward = _cage_on((0.04, 0.03, 0.064))
    reward.cage_margin_m = margin_m
    assert reward.gripper_command(0.04, 0.0) == 0.04
    reward.resume("pushing", 0)
    command = reward.gripper_command(0.04, 0.0)
    gap = reward.cage_gap_m - 2 * (0.04 - command)
    assert gap == pytest.approx(0.04 + 2 * margin_m), "a negative margin closes the fingers onto the object"


def test_cage_goes_back_over_the_top_when_the_object_is_behind_the_rear_finger():
    reward = _cage_on((0.04, 0.03, 0.04))
    com = reward.geometry.com_world
    cage = com + reward.cage_offset
    reward.update(np.concatenate([cage, com]))
    assert reward.state == "pushing"
    ahead_of_it = np.concatenate([cage + [0.01 + reward.cage_margin_m, 0.0, 0.0], com])
    assert not reward.out_of_cage(ahead_of_it), "leading by the press distance, the object is still caged"
    reward.update(ahead_of_it)
    assert reward.state == "pushing"
    run_ahead = np.concatenate([cage + [0.04, 0.0, 0.0], com])  # rear finger 2 cm past the object's centre
    assert reward.out_of_cage(run_ahead)
    reward.update(run_ahead)
    assert reward.state == "approaching"
    assert reward.gripper_command(0.04, 0.0) == 0.04, "fingers open to come down over it again"


def _one_finger_on(extents, hand=None) -> PushReward:
    x, y, z = extents
    box = np.array([[i, j, k] for i in (-x / 2, x / 2) for j in (-y / 2, y / 2) for k in (0.0, z)])
    geometry = TargetGeometry(np.array([0.0, 0.0, z / 2]), box, 0.0)
    return PushReward(
        hand=hand or poses_from(0), target=poses_from(3), geometry=geometry, qpos_offset=0, nq=7,
        goal_displacement=np.array([0.3, 0.0, 0.0]),
    )  # fmt: skip


def test_one_finger_approach_comes_down_behind_a_tall_object_not_beside_or_over_it():
    reward = _one_finger_on((0.04, 0.04, 0.16))
    centre = reward.geometry.com_world[None]
    reward.target_rot = np.eye(3)[None]
    contact = reward._contact_point(centre, reward.target_rot)
    direction = reward._direction(centre)
    top = 0.16 + reward.over_top_m

    def below_floor(hand):
        return float(reward.over_object_penalty(np.array([hand]), centre, contact, direction)[0])

    assert below_floor([0.0, 0.05, 0.05]) == pytest.approx(top - 0.05), "beside it, below its top"
    assert below_floor([0.0, 0.0, 0.15]) == pytest.approx(top - 0.15), "over it, fingers into its top"
    assert below_floor(contact[0]) == 0.0, "at the contact point"
    assert below_floor([-0.07, 0.01, 0.05]) == 0.0, "in the lane behind the contact point"
    assert below_floor([0.0, 0.05, top]) == 0.0, "above the top"
    assert below_floor([0.0, 0.2, 0.05]) == 0.0, "well away from it"
    reward.near_object_m = 0.0
    assert below_floor([0.0, 0.05, 0.05]) == 0.0, "off"


def test_one_finger_push_turns_the_palm_narrow_side_to_the_object():
    """The palm is long along the finger closing axis: across the push, its narrow side faces the object."""

    def hand(qpos):
        turned = qpos[..., 6] > 0.5  # closing axis along the push instead of across it
        down = np.diag([1.0, -1.0, -1.0])
        quarter = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
        return qpos[..., :3], np.where(turned[..., None, None], quarter, down)

    reward = _one_finger_on((0.04, 0.04, 0.16), hand)
    com = reward.geometry.com_world
    at = reward._contact_point(com[None], np.eye(3)[None])[0]
    states = np.array([[*at, *com, 0.0], [*at, *com, 1.0]])
    scores = reward(states, np.zeros((2, 0)))
    assert scores[0] - scores[1] == pytest.approx(reward.palm_yaw * np.pi / 2, abs=1e-4)


def _u_open_towards_the_finger() -> TargetGeometry:
    """A U 8 cm wide lying open towards -x (arms at |y| 2.5-4 cm reaching to x = -4 cm, its base at
    x 2-4 cm), 4 cm tall, with points over its surface."""
    at = trimesh.transformations.translation_matrix
    base = trimesh.creation.box(extents=(0.02, 0.08, 0.04), transform=at([0.03, 0, 0.02]))
    arms = [
        trimesh.creation.box(extents=(0.06, 0.015, 0.04), transform=at([-0.01, y, 0.02])) for y in (-0.0325, 0.0325)
    ]
    parts = trimesh.util.concatenate([base, *arms])
    geometry = TargetGeometry(np.array([0.0, 0.0, 0.02]), np.asarray(parts.vertices), 0.0)
    geometry.surface_points_world = sample_surface_points(parts, 3000, seed=0)
    return geometry


def test_one_finger_meets_a_u_open_towards_it_at_its_base_not_between_its_arms():
    geometry = _u_open_towards_the_finger()
    reward = PushReward(
        hand=None, target=None, geometry=geometry, qpos_offset=0, nq=0, goal_displacement=np.array([0.3, 0.0, 0.0])
    )
    centre = geometry.com_world[None]
    reward.target_rot = np.eye(3)[None]
    contact = reward._contact_point(centre, reward.target_rot, gap_m=0.0)[0]
    assert contact[0] == pytest.approx(0.02, abs=0.003), "the base's inner face, not the arms' ends at -0.04"
    assert contact[1] == pytest.approx(0.0)
    approach = reward._contact_point(centre, reward.target_rot)
    low_there = np.array([[*approach[0, :2], 0.03]])
    assert reward.over_object_penalty(low_there, centre, approach, reward._direction(centre))[0] == 0.0, (
        "between the arms, at the contact point, the hand is not over the object"
    )
    over_an_arm = np.array([[-0.02, 0.0325, 0.03]])
    assert reward.over_object_penalty(over_an_arm, centre, approach, reward._direction(centre))[0] > 0.0


def test_the_footprint_turns_with_the_object():
    """A 16 x 2 cm box: a hand 5 cm off its long side is 4 cm from it; turned a quarter, 5 cm along it is 0."""
    bar = trimesh.creation.box(
        extents=(0.16, 0.02, 0.04), transform=trimesh.transformations.translation_matrix([0, 0, 0.02])
    )
    geometry = TargetGeometry(np.array([0.0, 0.0, 0.02]), np.asarray(bar.vertices), 0.0)
    geometry.surface_points_world = sample_surface_points(bar, 2000, seed=0)
    reward = PushReward(hand=None, target=None, geometry=geometry, qpos_offset=0, nq=0)
    hand = np.array([[0.0, 0.05]])
    centre = geometry.com_world[None]
    quarter_turn = np.array([[[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]])
    assert reward._footprint_distance(hand, centre, np.eye(3)[None])[0] == pytest.approx(0.04, abs=0.003)
    assert reward._footprint_distance(hand, centre, quarter_turn)[0] == pytest.approx(0.0, abs=0.003)


def test_one_finger_backs_off_when_it_slips_round_to_the_objects_side():
    """A finger beside the object presses on its side face and pushes it off the line, though it is still
    near its contact point: it goes back to approaching, to come in behind the object again."""
    reward = _one_finger_on((0.05, 0.04, 0.06))
    com = reward.geometry.com_world
    contact = reward._contact_point(com[None], np.eye(3)[None])[0]
    reward.update(np.concatenate([contact, com]))
    assert reward.state == "pushing"
    reward.update(np.concatenate([contact + [0.0, 0.8 * reward.lane_half_width_m, 0.0], com]))
    assert reward.state == "pushing", "a little off the line, still behind it"
    beside = contact + [0.015, reward.lane_half_width_m + 0.005, 0.0]
    assert np.linalg.norm(beside - contact) < reward.disengage_distance_m
    reward.update(np.concatenate([beside, com]))
    assert reward.state == "approaching"
