"""Grasp and rearrange: come down on the target from above, close, then lift it (grasp) or carry it
to a goal and set it down (rearrange).

Paper reward, ungrasped/grasping: -d(hand, target) - 5 (hand height - 0.38 m) - 0.5 angle(hand, z).
Taken literally the height term rewards descending anywhere at five times the weight of closing
the distance, which drives the hand into whatever stands in front of the target. We keep its weight
(5) but apply it only below an approach funnel over the grasp point (height allowed to drop with
horizontal distance), so the hand comes down on the target from above. grasped: -d(hand, target)
- d(goal, object), as in the paper.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from arm_planner.finger_clearance import OpenFingers, clear_closing_axis
from arm_planner.grasp_site import GraspTarget, find_grasp_site, search_grasp_site
from arm_planner.tasks import GRASP_LIFT_M
from arm_planner.tasks.base import (
    TaskInfeasible,
    TaskReward,
    TaskSetup,
    angle_down,
    narrowest_horizontal_width_m,
    offsets_along,
    tilt_beyond,
    yaw_error,
)
from arm_planner.tasks.push import PUSH_STATES, push_reward

GRASP_STATES = ("ungrasped", "grasping", "grasped")


@dataclass
class GraspReward(TaskReward):
    """Grasp (goal = lifted by `lift_goal_m`) or rearrange (goal = start + displacement)."""

    goal_displacement: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.10]))
    close_steps: int = 75
    settle_steps: int = 10
    close_distance_m: float = 0.01
    stall_window: int = 10
    stall_eps_m: float = 0.002
    max_close_distance_m: float = 0.015
    # Grasp height: the centre of mass's, so gravity puts no torque about the closing axis, kept
    # between these depths below the top (the palm meets the top ~4.5 cm above the TCP) and 1.5 cm
    # above the table.
    grasp_min_depth_m: float = 0.015
    grasp_max_depth_m: float = 0.04
    # Rearrange: carry the object at least this high while it is far from the goal, set it down on
    # arrival; higher where other objects stand along the way, so that its base clears their tops by
    # `carry_clearance_m` (objects within its radius + `carry_corridor_margin_m` of the straight path),
    # up to `max_carry_height_m`.
    carry_height_m: float = 0.0
    # Rearrange: the hand's top speed while it holds the object, m/s (0: no cap).
    carry_speed_m_s: float = 0.0
    # Grasp: met once the target is lifted this far, m (0: a rearrange, met within tolerance of its goal).
    lift_to_meet_m: float = 0.0
    carry_clearance_m: float = 0.015
    carry_corridor_margin_m: float = 0.02
    max_carry_height_m: float = 0.10
    # Rearrange, once grasped, in three phases advanced on the executed state (`carry_phase`): lift
    # straight up to within `lift_first_within_m` of the carry height (moved sideways low, the object's
    # base drags on the table or meets the objects around it and pivots out of the fingers; after
    # `lift_timeout_steps` it is carried anyway), carry to above the goal, and place straight down once
    # within `place_within_m` of the goal horizontally (set down while moving, it tips over).
    lift_first_within_m: float = 0.01
    lift_timeout_steps: int = 100
    place_within_m: float = 0.02
    # Rearrange, while grasped: the hand's tilt from pointing down costs nothing up to this (radians);
    # beyond it, the angle weight per radian. Tilted 60-100 degrees, the object swings out of the
    # fingers; tilted 20-30, it turns in the grip and is set down leaning; penalised from 0, the
    # planner gave up the goal near joint limits to stay upright.
    carry_free_tilt_rad: float = float(np.radians(15.0))
    # Rearrange: the open fingers' inner gap (m; 0: unknown). When the object's extent along the carry
    # direction plus `carry_closing_margin_m` each side fits it, the fingers close along the carry
    # direction rather than across the object's narrowest extent: accelerating along the closing axis,
    # the object's inertia pushes on a finger, across it, it swings about the grip.
    finger_gap_open_m: float = 0.0
    carry_closing_margin_m: float = 0.01
    # The open fingers (None: unknown). With clear_fingers, a closing axis that would land a finger on
    # another object is turned, as little as it takes, to one where both fingers come down clear of it
    # and the object fits between them with carry_closing_margin_m each side (finger_clearance).
    fingers: OpenFingers | None = None
    clear_fingers: bool = True
    # Where the default site over the centre of mass has no material between the fingers (a ring, a
    # torus, a U) or a finger comes down on the target, grasp at the nearest site that holds it
    # squarely (grasp_site).
    search_grasp_site: bool = True
    grasp_site_moved: bool = False
    grasp_site_holds: bool = True  # False: neither the default site nor any other holds the target
    carry_phase: str = "lift"
    _history: list = field(default_factory=list)
    _closing_since: int = -1
    _closing_hold: np.ndarray | None = None  # where the hand holds while the fingers close (world, m)
    _grasped_since: int = 0

    def __post_init__(self):
        g = self.geometry
        self.start_com = g.com_world.copy()
        self.goal = g.com_world + self.goal_displacement
        z = np.clip(g.com_world[2], g.top_z - self.grasp_max_depth_m, g.top_z - self.grasp_min_depth_m)
        z = max(g.table_height_m + 0.015, float(z))
        self.grasp_point = np.array([g.com_world[0], g.com_world[1], z])
        self.closing_axis = self.geometry.minor_axis_xy()
        if self.fingers is not None and self.search_grasp_site:
            site = find_grasp_site(self.grasp_point, self.closing_axis, self._grasp_target(), self.fingers)
            self.grasp_point, self.closing_axis = site.point_world, site.axis_xy
            self.grasp_site_moved, self.grasp_site_holds = site.moved, site.holds
        self.grasp_offset = self.grasp_point - g.com_world
        # A moved site's axis already holds the target squarely and clears the other objects.
        if not self.grasp_site_moved and self.carry_height_m > 0 and self.finger_gap_open_m > 0:
            carry = np.append(self.goal_displacement[:2], 0.0)
            carry /= np.linalg.norm(carry) + 1e-9
            if self._fits_between(carry[:2], self.finger_gap_open_m):
                self.closing_axis = carry
        if self.fingers is not None and self.clear_fingers and not self.grasp_site_moved:
            self.closing_axis = clear_closing_axis(
                self.grasp_point,
                self.closing_axis,
                self.fingers,
                g.obstacle_halfspaces,
                fits=lambda axis_xy: self._fits_between(axis_xy, self.fingers.gap_m),
            )
        self._min_carry_height_m = self.carry_height_m
        if self.carry_height_m > 0:
            self.carry_height_m = self._clearing_height(g.bottom_z)

    def _grasp_target(self) -> GraspTarget:
        g = self.geometry
        return GraspTarget(
            g.com_world,
            g.vertices_world,
            g.part_halfspaces,
            g.table_height_m,
            self.grasp_min_depth_m,
            self.grasp_max_depth_m,
            g.obstacle_halfspaces,
        )

    @property
    def ungraspable(self) -> bool:
        """The target is wider than the open fingers along every horizontal axis (12 over half a turn)
        and no site on it has its material squarely between them (grasp_site): a parallel gripper
        cannot pick it up."""
        if self.fingers is None or not self.fingers.known or self.grasp_site_moved:
            return False
        if self.narrowest_width_m <= self.fingers.gap_m:
            return False
        return not self.grasp_site_holds or search_grasp_site(self._grasp_target(), self.fingers) is None

    @property
    def narrowest_width_m(self) -> float:
        """The target's least horizontal width over 12 directions across half a turn, m."""
        return narrowest_horizontal_width_m(self.geometry.vertices_world)

    def _fits_between(self, axis_xy: np.ndarray, gap_m: float) -> bool:
        """The target fits between fingers gap_m apart (m) closing along axis_xy, with
        carry_closing_margin_m to spare on each side."""
        return bool(np.ptp(offsets_along(self.geometry, axis_xy)) + 2 * self.carry_closing_margin_m <= gap_m)

    def _clearing_height(self, start_bottom_z: float) -> float:
        """Carry height (m above the start) whose base clears the objects between the target's centre
        and the goal, for a target whose base was at start_bottom_z (world z, m) at the start."""
        top = self.geometry.highest_obstacle_along(self.goal, self.carry_corridor_margin_m)
        needed = top + self.carry_clearance_m - start_bottom_z
        return float(np.clip(needed, self._min_carry_height_m, self.max_carry_height_m))

    @property
    def gripper_closed(self) -> bool:
        return self.state != "ungrasped"

    def carry_goal(self, target_pos: np.ndarray) -> np.ndarray:
        """Where the object should be: for a rearrange, while grasped, the start raised by
        carry_height_m (lifting), then the goal raised by it (carrying), then the goal (placing)."""
        point = self.goal
        if self.carry_height_m > 0 and self.state == "grasped" and self.carry_phase != "place":
            point = (self.start_com if self.carry_phase == "lift" else self.goal) + [0.0, 0.0, self.carry_height_m]
        return np.broadcast_to(point, np.shape(target_pos))

    def resume(self, state: str, steps_in_state: int) -> None:
        """Continue a task already under way (re-planning): grasping for `steps_in_state` steps, or grasped."""
        if state not in GRASP_STATES:
            raise ValueError(f"cannot resume a grasp in state {state!r}")
        self.state = state
        self._closing_since = self.step_count - int(steps_in_state)
        self._grasped_since = self._closing_since
        if self.carry_height_m > 0:
            # The start and goal are the task's (set before this), the geometry is where the object is
            # now: the carry height is measured from its base at the start, and a rearrange carried
            # away from its start, or lifted, carries on rather than lifting again.
            com = self.geometry.com_world
            self.carry_height_m = self._clearing_height(self.geometry.bottom_z - (com[2] - self.start_com[2]))
            if state == "grasped":
                moved = np.linalg.norm(com[:2] - self.start_com[:2]) > self.lift_first_within_m
                self._advance_carry_phase(com, lift_over=moved)

    def _advance_carry_phase(self, com: np.ndarray, lift_over: bool) -> None:
        """Lift -> carry once the object (centre of mass `com`, world m) is raised or `lift_over`;
        -> place once it is within place_within_m of the goal horizontally."""
        if self.carry_phase == "place":
            return
        if np.linalg.norm(com[:2] - self.goal[:2]) <= self.place_within_m:
            self.carry_phase = "place"
        elif self.carry_phase == "lift":
            raised = com[2] - self.start_com[2] >= self.carry_height_m - self.lift_first_within_m
            if raised or lift_over:
                self.carry_phase = "carry"

    def __call__(self, states: np.ndarray, controls: np.ndarray) -> np.ndarray:
        w = self.weights
        target_pos, hands = self.rollout_poses(states, controls)
        grasp_point = target_pos + self.grasp_offset
        if self.state == "grasping" and self._closing_hold is not None:
            # The hand holds the grasp site as it was when the fingers began to close: chasing an
            # object that a finger nudges drags it away (and tips it) before the grip forms.
            grasp_point = np.broadcast_to(self._closing_hold, grasp_point.shape)
        if self.state == "grasped":
            # The hand stays with the object. A rearrange scores it on the simulated hand only: the
            # commanded one sits above the held object by the arm's sag under load, and pulling it onto
            # the object lowered the carry until the object dragged on the table (the goal distance
            # hardly changes with height when the goal is far away). A grasp lifts straight up, against
            # the goal's full gradient; there the blend stays (simulated only, it lost 4 of 54 lifts).
            if self.carry_height_m <= 0:  # a grasp only lifts: no other term, as in the paper
                reach = self.blend(hands, lambda pos, rot: -w.distance * np.linalg.norm(pos - grasp_point, axis=-1))
            else:
                # Rearrange: the hand stays within carry_free_tilt_rad of pointing down, and while
                # carrying the object does not sink below the carry height.
                free = self.carry_free_tilt_rad
                _, simulated_hand_pos, _ = hands[0]
                reach = -w.distance * np.linalg.norm(simulated_hand_pos - grasp_point, axis=-1)
                reach = reach - self.blend(hands, lambda pos, rot: w.angle * tilt_beyond(rot, free))
                if self.carry_phase == "carry":
                    carry_z = self.goal[2] + self.carry_height_m
                    reach = reach - w.height * np.maximum(carry_z - target_pos[..., 2], 0.0)
            return reach - w.goal * np.linalg.norm(self.carry_goal(target_pos) - target_pos, axis=-1)

        def score(pos, rot):
            return (
                -w.distance * np.linalg.norm(pos - grasp_point, axis=-1)
                - w.height * self.funnel_penalty(pos, grasp_point)
                - w.angle * angle_down(rot)
                - w.yaw * yaw_error(rot, self.closing_axis)
            )

        return self.blend(hands, score)

    def update(self, state: np.ndarray) -> str:
        """Advance the state machine on the executed state; returns the new state name."""
        hand_pos, _, target_pos, _ = self.poses(state[None])
        site = target_pos[0] + self.grasp_offset
        distance = float(np.linalg.norm(hand_pos[0] - site))
        self._history.append(distance)
        self.step_count += 1
        if self.state == "ungrasped":
            n = self.step_count
            decreasing = n > self.stall_window and (self._history[-1 - self.stall_window] - distance > self.stall_eps_m)
            still_ungrasped = n < self.settle_steps or (distance > self.close_distance_m and decreasing)
            if not still_ungrasped and distance <= self.max_close_distance_m:
                self.state = "grasping"
                self._closing_since = n
                # The site, not the hand: the fingers begin to close up to max_close_distance_m
                # short of it (the hand still coming down), and holding there a lamp 6 cm tall on a
                # 2 cm base was knocked over by the closing fingers.
                self._closing_hold = site
        elif self.state == "grasping":
            if self._closing_hold is None:  # resumed mid-close: the fingers may already hold it
                self._closing_hold = hand_pos[0].copy()
            if self.step_count - self._closing_since >= self.close_steps:
                self.state = "grasped"
                self._grasped_since = self.step_count
        elif self.carry_height_m > 0:
            timed_out = self.step_count - self._grasped_since >= self.lift_timeout_steps
            self._advance_carry_phase(target_pos[0], lift_over=timed_out)
        return self.state

    def hand_speed_cap_m_s(self) -> float:
        return self.carry_speed_m_s if self.state == "grasped" else 0.0

    def holds_goal(self) -> bool:
        return self.state == "grasped"

    def met(self, com_world: np.ndarray, tolerance_m: float) -> tuple[bool, float]:
        if self.lift_to_meet_m <= 0:
            return super().met(com_world, tolerance_m)
        lift = float(com_world[2] - self.start_com[2])
        return lift >= self.lift_to_meet_m, max(0.0, self.lift_to_meet_m - lift)

    def error(self, state: np.ndarray) -> float:
        _, _, target_pos, _ = self.poses(state[None])
        return float(np.linalg.norm(self.goal - target_pos[0]))


def _grasp_reward(setup: TaskSetup, displacement: np.ndarray, carry_height_m: float) -> GraspReward:
    config, spec = setup.config, setup.robot
    return GraspReward(
        **setup.common,
        goal_displacement=displacement,
        close_steps=config.close_steps,
        carry_height_m=carry_height_m,
        finger_gap_open_m=spec.finger_gap_open_m if config.carry_closing_along else 0.0,
        fingers=setup.fingers,
        clear_fingers=config.clear_fingers,
        search_grasp_site=config.grasp_site_search,
    )


def grasp_task(setup: TaskSetup, request) -> GraspReward:
    """Lift the target towards grasp_lift_goal_m (met at GRASP_LIFT_M); TaskInfeasible when no site on
    it fits between the open fingers."""
    config = setup.config
    reward = _grasp_reward(setup, np.array([0.0, 0.0, config.grasp_lift_goal_m]), 0.0)
    if request.resume_state is None and reward.ungraspable:
        raise TaskInfeasible(
            f"the target is at least {reward.narrowest_width_m * 100:.1f} cm wide along every horizontal "
            f"axis, the open fingers hold {reward.fingers.gap_m * 100:.1f} cm, and no site "
            "on it fits between them: a parallel gripper cannot pick it up (push or rearrange it instead)"
        )
    reward.carry_speed_m_s = 0.0
    reward.lift_to_meet_m = GRASP_LIFT_M
    reward.step_budget = setup.step_budget(0)
    return reward


def rearrange_task(setup: TaskSetup, request):
    """Pick the target, carry it by the request's goal displacement and set it down; a target no grasp
    holds (push_ungraspable) is pushed there instead, and is then a push in every respect."""
    config = setup.config
    displacement = np.asarray(request.goal_displacement_m, dtype=np.float64)
    reward = _grasp_reward(setup, displacement, config.rearrange_carry_height_m)
    if request.resume_state in PUSH_STATES:  # re-planned after it became a push
        pushed = True
    elif request.resume_state in GRASP_STATES:
        pushed = False
    else:
        pushed = config.push_ungraspable and reward.ungraspable
    if pushed:
        return push_reward(setup, displacement)
    reward.carry_speed_m_s = config.carry_hand_speed_m_s
    reward.lift_to_meet_m = 0.0
    reward.step_budget = setup.step_budget(config.rearrange_steps)
    return reward
