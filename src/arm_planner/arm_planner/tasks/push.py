"""Push: the target slid across the table to a goal, by one finger leaning into the push or by the
open fingers caging it fore and aft (the push reward is not given in the paper; it uses the grasp's
terms: approach a point behind the object, opposite the goal direction, then push it there)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from arm_planner.tasks.base import TargetGeometry, TaskReward, TaskSetup, angle_down, offsets_along, yaw_error

PUSH_STATES = ("approaching", "pushing")
# Grid (m) the object's footprint is kept on, for the hand's distance to it.
FOOTPRINT_CELL_M = 0.003


@dataclass
class PushReward(TaskReward):
    """Approach a point behind the target (w.r.t. the goal direction) low over the table, then push."""

    goal_displacement: np.ndarray = field(default_factory=lambda: np.array([0.05, -0.30, 0.0]))
    # Hand target behind the object's surface: clear of it while approaching, 1 cm into it while
    # pushing (so that pressing on, not hovering at the surface, is what the reward pays for).
    contact_gap_m: float = 0.015
    push_gap_m: float = -0.01
    # The hand leans into the push by this angle (approach axis tilted from straight down towards the
    # push direction), so the fingertips, not the whole finger, meet the object low at its base: a
    # vertical finger presses on its full height and tips tall objects over.
    tilt_rad: float = 0.4
    contact_height_m: float = 0.018
    clearance_m: float = 0.012
    # While approaching, the hand (TCP) stays over_top_m above the object's top wherever its fingers
    # would meet the object (within finger_margin_m of its footprint) and, within near_object_m of the
    # footprint, outside the lane behind the contact point (at most lane_half_width_m + its distance
    # behind to the side of the push line): it comes down behind the object and slides in, rather
    # than sweeping its fingers or palm through a tall object on the way. near_object_m 0: off.
    # While pushing, a hand more than lane_half_width_m to the side of that line is beside the object
    # (update(): it backs off and approaches again).
    over_top_m: float = 0.02
    finger_margin_m: float = 0.012
    near_object_m: float = 0.1
    lane_half_width_m: float = 0.02
    # The lane starts this far ahead of the contact point (towards the object), m.
    lane_lead_m: float = 0.005
    # Half the finger's width (m): the finger coming in along the line through the object's centre
    # meets the surface within this of that line (the contact point).
    finger_half_width_m: float = 0.01
    # Per radian between the finger closing axis and the horizontal across the push: the palm, long
    # along the closing axis, then faces a tall object with its narrow side.
    palm_yaw: float = 0.2
    # While pushing, the hand rising more than this above the contact height costs as a scrape does:
    # the higher the finger presses, the sooner a tall object tips (when friction x height exceeds its
    # base's reach ahead of the centre of mass).
    rise_allowed_m: float = 0.01
    push_goal_weight: float = 10.0
    upright: float = 1.0
    engage_distance_m: float = 0.02
    disengage_distance_m: float = 0.06
    # While pushing, the goal terms score the rest point, where the object would stop sliding on its
    # own (x + v|v| / (2 mu g)), not where it is, so a push that would overshoot scores as one.
    # target_vel_adr: index of the target's free-joint linear velocity in the state vector (None: off).
    target_vel_adr: int | None = None
    friction: float = 0.9
    aim_beyond_m: float = 0.05
    # Push an object that slid past the goal back (needs a finger ahead of it: the cage).
    push_back_past_goal: bool = False
    # Object speed above sqrt(2 a d), d the distance still to go, is penalised (m/s^2, per m/s).
    braking_m_s2: float = 1.0
    speed_weight: float = 5.0
    # Within settled_m of the goal (rest point) the hand backs off to retreat_gap_m behind the object.
    settled_m: float = 0.015
    retreat_gap_m: float = 0.04
    state: str = "approaching"
    # Pushing, or the hand within disengage_distance_m of its contact point (set by update()).
    near_contact: bool = False
    # The hand's top speed while pushing or near its contact point, m/s (0: no cap).
    push_speed_m_s: float = 0.0

    def __post_init__(self):
        g = self.geometry
        self.start_com = g.com_world.copy()
        self.goal = g.com_world + self.goal_displacement
        height = g.top_z - g.bottom_z
        self.push_z = g.bottom_z + float(min(self.contact_height_m, 0.5 * height))
        points_world = g.surface_points()
        self._points_in_target = (points_world - g.com_world) @ np.asarray(g.R_world_target, dtype=np.float64)
        # The finger leans into the push, so a part of the object at height z above the contact
        # height meets the finger tan(tilt) (z - contact height) later than one at the contact height:
        # the contact point is the first point of the object that the leaning finger meets, not the
        # object's widest part (an overhanging top would put the fingertip in the air beside a thin
        # base and the finger against the top, which tips the object over).
        above = np.maximum(points_world[:, 2] - self.push_z, 0.0)
        self._lean_setback = above * np.tan(self.tilt_rad)
        # The footprint, where points over the surface are known (the twin gives them); else None.
        self._footprint_xy = None
        if len(g.surface_points_world):
            cells = np.unique(np.round((points_world[:, :2] - g.com_world[:2]) / FOOTPRINT_CELL_M), axis=0)
            self._footprint_xy = cells * FOOTPRINT_CELL_M

    @property
    def gripper_closed(self) -> bool:
        return True

    def resume(self, state: str, steps_in_state: int) -> None:
        if state not in PUSH_STATES:
            raise ValueError(f"cannot resume a push in state {state!r}")
        self.state = state
        self.near_contact = state == "pushing"

    def _direction(self, target_pos: np.ndarray) -> np.ndarray:
        """Push direction: towards a point aim_beyond_m past the goal along the commanded displacement,
        which corrects sideways drift but does not swing round when the object is at the goal. With
        push_back_past_goal, an object past the goal along the displacement is aimed back, aim_beyond_m
        short of the goal."""
        nominal = self._nominal_xy()
        beyond = np.full(target_pos.shape[:-1], self.aim_beyond_m)
        if self.push_back_past_goal:
            beyond = np.where(self._past_goal(target_pos), -beyond, beyond)
        to_aim = self.goal[:2] + beyond[..., None] * nominal - target_pos[..., :2]
        return to_aim / (np.linalg.norm(to_aim, axis=-1, keepdims=True) + 1e-9)

    def _nominal_xy(self) -> np.ndarray:
        """Unit horizontal direction of the commanded displacement."""
        return self.goal_displacement[:2] / (np.linalg.norm(self.goal_displacement[:2]) + 1e-9)

    def _past_goal(self, xy: np.ndarray) -> np.ndarray:
        """Per position (world xy..., m): beyond the goal along the commanded displacement."""
        return (xy[..., :2] - self.goal[:2]) @ self._nominal_xy() > 0.0

    def _approach_axis(self, target_pos: np.ndarray) -> np.ndarray:
        direction = self._direction(target_pos) * np.sin(self.tilt_rad)
        down = np.full(direction.shape[:-1] + (1,), -np.cos(self.tilt_rad))
        return np.concatenate([direction, down], axis=-1)

    def _contact_point(self, target_pos: np.ndarray, target_rot: np.ndarray, gap_m=None) -> np.ndarray:
        """The hand's target gap_m behind the object's surface, opposite the push direction, at the
        object's pose (target_pos, target_rot): it turns with the object as the push turns it."""
        gap_m = self.contact_gap_m if gap_m is None else gap_m
        direction = self._direction(target_pos)
        reach = self._support_batch(-direction, target_rot)
        xy = target_pos[..., :2] - direction * (reach + np.asarray(gap_m))[..., None]
        z = np.broadcast_to(self.push_z + (target_pos[..., 2] - self.geometry.com_world[2]), xy.shape[:-1])
        return np.concatenate([xy, z[..., None]], axis=-1)

    def _support_batch(self, directions_xy: np.ndarray, target_rot: np.ndarray, lean: bool = True) -> np.ndarray:
        """How far the rotated object reaches from its centre along each horizontal unit direction (m):
        with lean, where the leaning finger coming in along the line through the centre meets it (its
        surface within finger_half_width_m of that line, all of it when none lies there: a U open
        towards the finger is met at its base, not in the air between its arms); else anywhere."""
        zeros = np.zeros(directions_xy.shape[:-1] + (1,))
        directions = np.concatenate([directions_xy, zeros], axis=-1)
        reach = np.einsum("...ji,...j->...i", target_rot, directions) @ self._points_in_target.T
        if not lean:
            return reach.max(axis=-1)
        across = np.concatenate([-directions_xy[..., 1:], directions_xy[..., :1], zeros], axis=-1)
        aside = np.einsum("...ji,...j->...i", target_rot, across) @ self._points_in_target.T
        reach -= self._lean_setback
        off_line = np.abs(aside) > self.finger_half_width_m
        nearest_on_line = np.where(off_line, -np.inf, reach).max(axis=-1)
        return np.where(np.isfinite(nearest_on_line), nearest_on_line, reach.max(axis=-1))

    def _footprint_distance(self, hand_xy: np.ndarray, target_pos: np.ndarray, target_rot: np.ndarray) -> np.ndarray:
        """Horizontal distance (m) from each hand position to the object's footprint (its surface points
        seen from above at planning start, on a FOOTPRINT_CELL_M grid), turned by the object's yaw since."""
        turned = target_rot @ np.asarray(self.geometry.R_world_target, dtype=np.float64).T
        yaw_cos, yaw_sin = turned[..., 0, 0], turned[..., 1, 0]
        scale = np.hypot(yaw_cos, yaw_sin) + 1e-12
        x, y = np.moveaxis(hand_xy - target_pos[..., :2], -1, 0)
        local = np.stack([yaw_cos * x + yaw_sin * y, yaw_cos * y - yaw_sin * x], axis=-1) / scale[..., None]
        footprint = self._footprint_xy
        squared = np.sum(footprint**2, axis=-1) - 2.0 * local @ footprint.T
        return np.sqrt(np.maximum(squared.min(axis=-1) + np.sum(local**2, axis=-1), 0.0))

    def rest_xy(self, states: np.ndarray, target_pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(where the target would stop sliding on its own (world xy, m), its speed (m/s)) per state."""
        if self.target_vel_adr is None:
            return target_pos[..., :2], np.zeros(target_pos.shape[:-1])
        velocity = states[..., self.target_vel_adr : self.target_vel_adr + 2]
        speed = np.linalg.norm(velocity, axis=-1)
        return target_pos[..., :2] + velocity * (speed / (2.0 * self.friction * 9.81))[..., None], speed

    def __call__(self, states: np.ndarray, controls: np.ndarray) -> np.ndarray:
        w = self.weights
        target_pos, hands = self.rollout_poses(states, controls)
        pushing = self.state == "pushing"
        rest, speed = self.rest_xy(states, target_pos)
        to_go = np.linalg.norm(self.goal[:2] - rest, axis=-1)
        settled = to_go < self.settled_m
        if not self.push_back_past_goal:
            # One finger cannot bring back an object that will come to rest past the goal: pushing on
            # only takes it further, so the hand backs off as it does at the goal.
            settled |= self._past_goal(rest)
        gap = np.where(settled, self.retreat_gap_m, self.push_gap_m if pushing else self.contact_gap_m)
        contact = self._contact_point(target_pos, self.target_rot, gap)
        axis = self._approach_axis(target_pos)
        direction = self._direction(target_pos)
        across = np.stack([-direction[..., 1], direction[..., 0]], axis=-1)

        def score(pos, rot):
            lean = np.arccos(np.clip(np.einsum("...i,...i->...", rot[..., :, 2], axis), -1.0, 1.0))
            value = -w.distance * np.linalg.norm(pos - contact, axis=-1) - w.angle * lean
            value = value - self.palm_yaw * yaw_error(rot, across)
            scrape = np.maximum(self.geometry.table_height_m + self.clearance_m - pos[..., 2], 0.0)
            value = value - w.height * scrape
            if pushing:
                return value - w.height * np.maximum(pos[..., 2] - contact[..., 2] - self.rise_allowed_m, 0.0)
            below = self.funnel_penalty(pos, contact) + self.over_object_penalty(pos, target_pos, contact, direction)
            return value - w.height * below

        reward = self.blend(hands, score)
        if pushing:
            reward = self._with_pushing_terms(reward, to_go, speed)
        return reward

    def over_object_penalty(
        self, hand_pos: np.ndarray, target_pos: np.ndarray, contact: np.ndarray, direction: np.ndarray
    ) -> np.ndarray:
        """How far (m) the hand is below over_top_m above the object's top where it would meet the
        object on its way to the contact point (see over_top_m); direction: the push's, unit xy."""
        if self.near_object_m <= 0:
            return np.zeros(hand_pos.shape[:-1])
        offset = hand_pos[..., :2] - target_pos[..., :2]
        distance = np.linalg.norm(offset, axis=-1)
        reach = self._support_batch(offset / (distance[..., None] + 1e-9), self.target_rot, lean=False)
        from_contact = hand_pos[..., :2] - contact[..., :2]
        behind = -np.sum(from_contact * direction, axis=-1)
        aside = np.abs(from_contact[..., 0] * direction[..., 1] - from_contact[..., 1] * direction[..., 0])
        in_lane = (behind >= -self.lane_lead_m) & (aside <= self.lane_half_width_m + np.maximum(behind, 0.0))
        if self._footprint_xy is None:  # vertices only: the reach along the hand's bearing stands for it
            on_footprint = distance < reach + self.finger_margin_m
        else:
            footprint_distance = self._footprint_distance(hand_pos[..., :2], target_pos, self.target_rot)
            on_footprint = footprint_distance < self.finger_margin_m
        over = on_footprint | ((distance < reach + self.near_object_m) & ~in_lane)
        top = self.geometry.top_z + (target_pos[..., 2] - self.geometry.com_world[2]) + self.over_top_m
        return np.where(over, np.maximum(top - hand_pos[..., 2], 0.0), 0.0)

    def _with_pushing_terms(self, reward: np.ndarray, to_go: np.ndarray, speed: np.ndarray, free_tilt_rad=0.0):
        """reward less, while pushing: the rest point's distance to the goal, object speed the hand could
        not stop from, and the object's tilt beyond free_tilt_rad."""
        w = self.weights
        tilt = np.arccos(np.clip(self.target_rot[..., 2, 2], -1.0, 1.0))
        reward = reward - w.goal * self.push_goal_weight * to_go
        braking = np.sqrt(2.0 * self.braking_m_s2 * to_go)  # the speed the hand can still stop from
        reward = reward - self.speed_weight * np.maximum(speed - braking, 0.0)
        return reward - self.upright * np.maximum(tilt - free_tilt_rad, 0.0)

    def _engage_distance(self, state: np.ndarray) -> float:
        """The hand's distance (m) from where it engages the object, at an executed state."""
        hand_pos, _, target_pos, target_rot = self.poses(state[None])
        return float(np.linalg.norm(hand_pos[0] - self._contact_point(target_pos, target_rot)[0]))

    def _beside_object(self, state: np.ndarray) -> bool:
        """Whether the hand, at an executed state, is further than lane_half_width_m to the side of the
        push line through its contact point: there it presses on the object's side and pushes it off
        the line (a hand that slipped round a corner), so it backs off and comes in behind again."""
        hand_pos, _, target_pos, target_rot = self.poses(state[None])
        direction = self._direction(target_pos)[0]
        from_contact = hand_pos[0, :2] - self._contact_point(target_pos, target_rot)[0, :2]
        return abs(from_contact[0] * direction[1] - from_contact[1] * direction[0]) > self.lane_half_width_m

    def update(self, state: np.ndarray) -> str:
        distance = self._engage_distance(state)
        self.step_count += 1
        if self.state == "approaching" and distance < self.engage_distance_m:
            self.state = "pushing"
        elif self.state == "pushing" and (distance > self.disengage_distance_m or self._beside_object(state)):
            self.state = "approaching"
        self.near_contact = self.state == "pushing" or distance < self.disengage_distance_m
        return self.state

    def hand_speed_cap_m_s(self) -> float:
        return self.push_speed_m_s if self.near_contact else 0.0

    def error(self, state: np.ndarray) -> float:
        _, _, target_pos, _ = self.poses(state[None])
        return float(np.linalg.norm(self.goal - target_pos[0]))


@dataclass
class CagePushReward(PushReward):
    """Push with the open fingers straddling the object fore and aft along the push (a cage).

    The rear finger pushes low and the front one catches the object if it starts to tip, so the push
    does not depend on where the hidden shape first meets a finger (a single finger pushing a
    top-heavy object tips it unless friction x contact height < the base's reach ahead of the centre
    of mass; `bench_pushability`). Used for objects that fit between the open fingers
    (`fits_cage`); the hand comes down vertically over the middle of the object's extent along the
    push, fingertips just above the table, and then moves with the object to the goal.
    """

    # The robot's open fingers: inner gap (m), fingertip to palm (m), TCP above the fingertips (m).
    cage_gap_m: float = 0.082
    finger_length_m: float = 0.055
    tcp_above_fingertip_m: float = 0.007
    tip_clearance_m: float = 0.010
    palm_clearance_m: float = 0.005
    # While pushing, the fingers close to the object's extent along the push plus this each side
    # (negative: onto it), and the hand aims this far forward of the cage's middle, so the rear finger
    # presses on the object. The planner sets it from PlannerConfig.push_cage_margin_m.
    cage_margin_m: float = 0.0
    press_m: float = 0.01
    # Per radian between the finger closing axis and the push direction.
    cage_yaw: float = 0.5
    # The object may lean this far (rad) into the front finger unpenalised: pushed by the rear finger
    # it leans until the front one holds it.
    cage_tilt_rad: float = 0.3
    # The front finger pushes back an object that slid past the goal in the world but not in the twin.
    push_back_past_goal: bool = True
    # The object counts as out of the cage when its centre lies this far behind the rear finger (m).
    out_of_cage_m: float = 0.005

    def __post_init__(self):
        g = self.geometry
        self.start_com = g.com_world.copy()
        self.goal = g.com_world + self.goal_displacement
        direction = self._direction(g.com_world[None])[0]
        along = offsets_along(g, direction)
        self.extent_along_m = float(along.max() - along.min())
        self.slack_m = 0.5 * (self.cage_gap_m - self.extent_along_m)
        tip_z = max(g.bottom_z + self.tip_clearance_m, g.top_z + self.palm_clearance_m - self.finger_length_m)
        cage = np.array([*(g.com_world[:2] + direction * 0.5 * (along.max() + along.min())), 0.0])
        cage[2] = tip_z + self.tcp_above_fingertip_m
        self.cage_offset = cage - g.com_world
        # While the hand is further than the slack from the cage point, its fingertips stay this much
        # above the object's top.
        self._rise_m = g.top_z + self.tip_clearance_m - tip_z

    @classmethod
    def fits_cage(
        cls,
        geometry: TargetGeometry,
        goal_displacement: np.ndarray,
        cage_gap_m: float,
        finger_length_m: float,
        margin_m: float = 0.008,
        max_tip_height_m: float = 0.03,
    ) -> bool:
        """Whether the object fits between open fingers cage_gap_m apart along the push, with margin_m
        each side, and under the palm with the fingertips at most max_tip_height_m above its bottom."""
        if cage_gap_m <= 0:
            return False
        direction = np.asarray(goal_displacement, dtype=np.float64)[:2]
        along = offsets_along(geometry, direction / (np.linalg.norm(direction) + 1e-9))
        height = geometry.top_z - geometry.bottom_z
        return float(np.ptp(along)) + 2 * margin_m <= cage_gap_m and height <= finger_length_m + max_tip_height_m

    def cage_funnel_penalty(self, hand_pos: np.ndarray, cage: np.ndarray) -> np.ndarray:
        """How far (m) the hand is below the height at which its fingertips clear the object's top,
        while it is further than the cage's slack from the cage point horizontally."""
        d_xy = np.linalg.norm(hand_pos[..., :2] - cage[..., :2], axis=-1)
        margin = max(self.slack_m - 0.003, 0.002)
        floor = cage[..., 2] + self._rise_m * np.clip((d_xy - margin) / 0.005, 0.0, 1.0)
        return np.maximum(floor - hand_pos[..., 2], 0.0)

    @property
    def gripper_closed(self) -> bool:
        return False

    def gripper_command(self, open_command: float, closed_command: float) -> float:
        """Open while approaching; while pushing, closed to the object's extent along the push plus
        cage_margin_m each side (the inner gap changes by twice the command of one finger)."""
        if self.state != "pushing":
            return open_command
        narrower_by = self.cage_gap_m - (self.extent_along_m + 2 * self.cage_margin_m)
        command = open_command - np.sign(open_command - closed_command) * max(narrower_by, 0.0) / 2
        return float(np.clip(command, min(open_command, closed_command), max(open_command, closed_command)))

    def __call__(self, states: np.ndarray, controls: np.ndarray) -> np.ndarray:
        w = self.weights
        target_pos, hands = self.rollout_poses(states, controls)
        pushing = self.state == "pushing"
        direction = self._direction(target_pos)
        cage = target_pos + self.cage_offset
        if pushing:
            lead = self.cage_margin_m + self.press_m
            cage = cage + np.concatenate([direction * lead, np.zeros(direction.shape[:-1] + (1,))], axis=-1)

        def score(pos, rot):
            value = (
                -w.distance * np.linalg.norm(pos - cage, axis=-1)
                - w.angle * angle_down(rot)
                - self.cage_yaw * yaw_error(rot, direction)
            )
            scrape = np.maximum(self.geometry.table_height_m + self.clearance_m - pos[..., 2], 0.0)
            value = value - w.height * scrape
            return value if pushing else value - w.height * self.cage_funnel_penalty(pos, cage)

        reward = self.blend(hands, score)
        if pushing:
            rest, speed = self.rest_xy(states, target_pos)
            to_go = np.linalg.norm(self.goal[:2] - rest, axis=-1)
            reward = self._with_pushing_terms(reward, to_go, speed, self.cage_tilt_rad)
        return reward

    def _engage_distance(self, state: np.ndarray) -> float:
        hand_pos, _, target_pos, _ = self.poses(state[None])
        return float(np.linalg.norm(hand_pos[0] - (target_pos[0] + self.cage_offset)))

    def _beside_object(self, state: np.ndarray) -> bool:
        """Never: the open fingers straddle the object (out_of_cage tells when it slipped out)."""
        return False

    def out_of_cage(self, state: np.ndarray) -> bool:
        """Whether the object's centre lies behind the rear finger (by out_of_cage_m) at an executed
        state: it slipped out of the cage (or the hand ran ahead of it)."""
        hand_pos, _, target_pos, _ = self.poses(state[None])
        direction = self._direction(target_pos)[0]
        along = float((target_pos[0, :2] - hand_pos[0, :2]) @ direction)
        return along < -(0.5 * self.extent_along_m + self.cage_margin_m + self.out_of_cage_m)

    def update(self, state: np.ndarray) -> str:
        """As PushReward.update, and back to approaching (over the top, fingers open) when the object
        is out of the cage: closed on an object behind it, the cage can only push it the wrong way."""
        super().update(state)
        if self.state == "pushing" and self.out_of_cage(state):
            self.state = "approaching"
        return self.state


def push_reward(setup: TaskSetup, displacement: np.ndarray) -> PushReward:
    """The caging push when the target fits between the open fingers (and push_cage is on), else the
    one-finger push; its speed cap and step budget from the planner's settings."""
    config, spec = setup.config, setup.robot
    push = dict(
        setup.common,
        goal_displacement=displacement,
        target_vel_adr=setup.target_vel_adr,
        friction=config.object_friction,
    )
    if config.push_cage and CagePushReward.fits_cage(
        setup.common["geometry"], displacement, spec.finger_gap_open_m, spec.fingertip_to_palm_m
    ):
        reward = CagePushReward(
            **push,
            cage_gap_m=spec.finger_gap_open_m,
            cage_margin_m=config.push_cage_margin_m,
            finger_length_m=spec.fingertip_to_palm_m,
            tcp_above_fingertip_m=spec.tcp_above_fingertip_m,
        )
    else:
        reward = PushReward(**push, contact_height_m=config.push_contact_height_m)
    reward.push_speed_m_s = config.push_hand_speed_m_s
    reward.step_budget = setup.step_budget(config.push_steps)
    return reward


def push_task(setup: TaskSetup, request) -> PushReward:
    """Push the target by the request's goal displacement."""
    return push_reward(setup, np.asarray(request.goal_displacement_m, dtype=np.float64))
