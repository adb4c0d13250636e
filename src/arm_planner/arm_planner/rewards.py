"""Stateful task rewards for MPPI: grasp, push, rearrange.

Each reward scores rollouts (batched, vectorised over paths and horizon) and keeps a small state
machine that advances only on the executed trajectory, as in the paper's appendix "MPPI
Parameters": ungrasped -> grasping (gripper closes for `close_steps`) -> grasped.

Paper reward, ungrasped/grasping: -d(hand, target) - 5 (hand height - 0.38 m) - 0.5 angle(hand, z).
Taken literally the height term rewards descending anywhere at five times the weight of closing
the distance, which drives the hand into whatever stands in front of the target. We keep its weight
(5) but apply it only below an approach funnel over the grasp point (height allowed to drop with
horizontal distance), so the hand comes down on the target from above. grasped: -d(hand, target)
- d(goal, object), as in the paper. The push reward (not given in the paper) uses the same terms:
approach a point behind the object (opposite the goal direction), then push it to the goal.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from arm_planner.finger_clearance import OpenFingers, clear_closing_axis
from arm_planner.kinematics import BodyKinematics

TASK_GRASP = "grasp"
TASK_PUSH = "push"
TASK_REARRANGE = "rearrange"
TASKS = (TASK_GRASP, TASK_PUSH, TASK_REARRANGE)
GRASP_LIFT_M = 0.05


@dataclass
class TargetGeometry:
    """The target in the twin at planning start, world frame; R_world_target is its body's rotation."""

    com_world: np.ndarray
    vertices_world: np.ndarray
    table_height_m: float
    R_world_target: np.ndarray = field(default_factory=lambda: np.eye(3))
    # Vertices of the other objects in the twin at planning start, world frame (metres).
    obstacle_vertices_world: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    # Their convex parts as [F, 4] half-spaces (finger_clearance.halfspaces), world frame.
    obstacle_halfspaces: list = field(default_factory=list)

    def vertices_in_target(self) -> np.ndarray:
        """Vertices relative to the centre of mass, in the target body's frame (metres)."""
        return (self.vertices_world - self.com_world) @ np.asarray(self.R_world_target, dtype=np.float64)

    @property
    def top_z(self) -> float:
        return float(self.vertices_world[:, 2].max())

    @property
    def bottom_z(self) -> float:
        return float(self.vertices_world[:, 2].min())

    def highest_obstacle_along(self, goal_xy: np.ndarray, margin_m: float) -> float:
        """Top (world z, m) of the other objects within the target's horizontal radius + margin_m of
        the straight path from its centre to goal_xy; the table height when none is."""
        obstacles = self.obstacle_vertices_world
        if len(obstacles) == 0:
            return self.table_height_m
        start = self.com_world[:2]
        path = np.asarray(goal_xy, dtype=np.float64)[:2] - start
        t = np.clip((obstacles[:, :2] - start) @ path / max(float(path @ path), 1e-12), 0.0, 1.0)
        off_path = np.linalg.norm(obstacles[:, :2] - (start + t[:, None] * path), axis=1)
        radius = float(np.linalg.norm(self.vertices_world[:, :2] - start, axis=1).max())
        near = off_path <= radius + margin_m
        return float(obstacles[near, 2].max()) if near.any() else self.table_height_m

    def minor_axis_xy(self) -> np.ndarray:
        """Unit horizontal direction of the object's smallest horizontal extent (grasp closing axis)."""
        xy = self.vertices_world[:, :2] - self.vertices_world[:, :2].mean(axis=0)
        cov = xy.T @ xy / max(len(xy), 1)
        _, vecs = np.linalg.eigh(cov)
        return np.append(vecs[:, 0], 0.0)


@dataclass
class RewardWeights:
    distance: float = 1.0
    height: float = 5.0
    angle: float = 0.5
    yaw: float = 0.2
    goal: float = 1.0
    # Share of the hand terms scored on the commanded pose (FK of the servo targets) rather than the
    # simulated one. The servos lag their targets by ~0.1 s, the whole 5-step horizon, so without it
    # a target change barely shows in the horizon's rewards.
    command: float = 0.5
    # Approach funnel: allowed height above the grasp/push point per metre of horizontal distance.
    funnel_slope: float = 1.0
    funnel_margin_m: float = 0.02


def _angle_down(rot: np.ndarray) -> np.ndarray:
    """Angle between the hand's approach axis (its z axis) and world -z, radians."""
    return np.arccos(np.clip(-rot[..., 2, 2], -1.0, 1.0))


def _tilt_beyond(rot: np.ndarray, free_rad: float) -> np.ndarray:
    """How far (radians) the hand's approach axis tilts from world -z beyond free_rad; 0 within it."""
    return np.maximum(_angle_down(rot) - free_rad, 0.0)


def _yaw_error(rot: np.ndarray, axis_xy: np.ndarray) -> np.ndarray:
    """Angle between the finger closing axis (hand y) and a horizontal axis, modulo pi."""
    fingers = rot[..., :2, 1]
    norm = np.linalg.norm(fingers, axis=-1) + 1e-9
    along = np.abs(np.sum(fingers * np.asarray(axis_xy)[..., :2], axis=-1))
    return np.arccos(np.clip(along / norm, 0.0, 1.0))


@dataclass
class TaskReward:
    """Shared machinery: hand and target kinematics from qpos, state, step counter."""

    hand: BodyKinematics
    target: BodyKinematics
    geometry: TargetGeometry
    qpos_offset: int
    nq: int
    arm_qpos_adr: np.ndarray | None = None
    arm_actuators: np.ndarray | None = None
    weights: RewardWeights = field(default_factory=RewardWeights)
    state: str = "ungrasped"
    step_count: int = 0

    def poses(self, states: np.ndarray):
        """(hand position, hand rotation, target centre, target rotation) per state, world frame."""
        qpos = states[..., self.qpos_offset : self.qpos_offset + self.nq]
        hand_pos, hand_rot = self.hand(qpos)
        target_pos, target_rot = self.target(qpos)
        return hand_pos, hand_rot, target_pos, target_rot

    def rollout_poses(self, states: np.ndarray, controls: np.ndarray):
        """(target centre, hand poses): the simulated hand and, if blended, the commanded one."""
        qpos = states[..., self.qpos_offset : self.qpos_offset + self.nq]
        target_pos, self.target_rot = self.target(qpos)
        hands = [(1.0, *self.hand(qpos))]
        share = self.weights.command
        if share > 0 and self.arm_qpos_adr is not None:
            commanded_qpos = qpos.copy()
            commanded_qpos[..., self.arm_qpos_adr] = controls[..., self.arm_actuators]
            hands = [(1.0 - share, *hands[0][1:]), (share, *self.hand(commanded_qpos))]
        return target_pos, hands

    def gripper_command(self, open_command: float, closed_command: float) -> float:
        """The gripper actuator's target for the next step, from the robot's open and closed values."""
        return closed_command if self.gripper_closed else open_command

    @staticmethod
    def blend(hands, score) -> np.ndarray:
        """score(hand_pos, hand_rot) weighted over the simulated and commanded hand poses."""
        return sum(weight * score(pos, rot) for weight, pos, rot in hands)

    def funnel_penalty(self, hand_pos: np.ndarray, point: np.ndarray) -> np.ndarray:
        w = self.weights
        d_xy = np.linalg.norm(hand_pos[..., :2] - point[..., :2], axis=-1)
        floor = point[..., 2] + w.funnel_slope * np.maximum(d_xy - w.funnel_margin_m, 0.0)
        return np.maximum(floor - hand_pos[..., 2], 0.0)


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
    # beyond it, the angle weight per radian (tilted 60-100 degrees, the object swings out of the
    # fingers; penalised from 0, the planner gave up the goal near joint limits to stay upright).
    carry_free_tilt_rad: float = float(np.radians(30.0))
    # Rearrange: the open fingers' inner gap (m; 0: unknown). When the object's extent along the carry
    # direction plus `carry_closing_margin_m` each side fits it, the fingers close along the carry
    # direction rather than across the object's narrowest extent: accelerating along the closing axis,
    # the object's inertia pushes on a finger, across it, it swings about the grip.
    finger_gap_open_m: float = 0.0
    carry_closing_margin_m: float = 0.01
    # The open fingers (None: unknown). A closing axis that would land a finger on another object is
    # turned, as little as it takes, to one where both fingers come down clear of it and the object
    # fits between them with carry_closing_margin_m each side (finger_clearance).
    fingers: OpenFingers | None = None
    carry_phase: str = "lift"
    _history: list = field(default_factory=list)
    _closing_since: int = -1
    _closing_hand_pos: np.ndarray | None = None
    _grasped_since: int = 0

    def __post_init__(self):
        g = self.geometry
        self.start_com = g.com_world.copy()
        self.goal = g.com_world + self.goal_displacement
        z = np.clip(g.com_world[2], g.top_z - self.grasp_max_depth_m, g.top_z - self.grasp_min_depth_m)
        z = max(g.table_height_m + 0.015, float(z))
        self.grasp_point = np.array([g.com_world[0], g.com_world[1], z])
        self.grasp_offset = self.grasp_point - g.com_world
        self.closing_axis = self.geometry.minor_axis_xy()
        if self.carry_height_m > 0 and self.finger_gap_open_m > 0:
            carry = np.append(self.goal_displacement[:2], 0.0)
            carry /= np.linalg.norm(carry) + 1e-9
            if self._fits_between(carry[:2], self.finger_gap_open_m):
                self.closing_axis = carry
        if self.fingers is not None:
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

    def _fits_between(self, axis_xy: np.ndarray, gap_m: float) -> bool:
        """The target fits between fingers gap_m apart (m) closing along axis_xy, with
        carry_closing_margin_m to spare on each side."""
        return bool(np.ptp(_offsets_along(self.geometry, axis_xy)) + 2 * self.carry_closing_margin_m <= gap_m)

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
        if state not in ("ungrasped", "grasping", "grasped"):
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
        if self.state == "grasping" and self._closing_hand_pos is not None:
            # The hand holds where the fingers began to close: chasing an object that a finger nudges
            # drags it away (and tips it) before the grip forms.
            grasp_point = np.broadcast_to(self._closing_hand_pos, grasp_point.shape)
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
                reach = reach - self.blend(hands, lambda pos, rot: w.angle * _tilt_beyond(rot, free))
                if self.carry_phase == "carry":
                    carry_z = self.goal[2] + self.carry_height_m
                    reach = reach - w.height * np.maximum(carry_z - target_pos[..., 2], 0.0)
            return reach - w.goal * np.linalg.norm(self.carry_goal(target_pos) - target_pos, axis=-1)

        def score(pos, rot):
            return (
                -w.distance * np.linalg.norm(pos - grasp_point, axis=-1)
                - w.height * self.funnel_penalty(pos, grasp_point)
                - w.angle * _angle_down(rot)
                - w.yaw * _yaw_error(rot, self.closing_axis)
            )

        return self.blend(hands, score)

    def update(self, state: np.ndarray) -> str:
        """Advance the state machine on the executed state; returns the new state name."""
        hand_pos, _, target_pos, _ = self.poses(state[None])
        distance = float(np.linalg.norm(hand_pos[0] - (target_pos[0] + self.grasp_offset)))
        self._history.append(distance)
        self.step_count += 1
        if self.state == "ungrasped":
            n = self.step_count
            decreasing = n > self.stall_window and (self._history[-1 - self.stall_window] - distance > self.stall_eps_m)
            still_ungrasped = n < self.settle_steps or (distance > self.close_distance_m and decreasing)
            if not still_ungrasped and distance <= self.max_close_distance_m:
                self.state = "grasping"
                self._closing_since = n
                self._closing_hand_pos = hand_pos[0].copy()
        elif self.state == "grasping":
            if self._closing_hand_pos is None:  # resumed mid-close
                self._closing_hand_pos = hand_pos[0].copy()
            if self.step_count - self._closing_since >= self.close_steps:
                self.state = "grasped"
                self._grasped_since = self.step_count
        elif self.carry_height_m > 0:
            timed_out = self.step_count - self._grasped_since >= self.lift_timeout_steps
            self._advance_carry_phase(target_pos[0], lift_over=timed_out)
        return self.state

    def error(self, state: np.ndarray) -> float:
        _, _, target_pos, _ = self.poses(state[None])
        return float(np.linalg.norm(self.goal - target_pos[0]))


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

    def __post_init__(self):
        g = self.geometry
        self.start_com = g.com_world.copy()
        self.goal = g.com_world + self.goal_displacement
        height = g.top_z - g.bottom_z
        self.push_z = g.bottom_z + float(min(self.contact_height_m, 0.5 * height))
        self._vertices_in_target = g.vertices_in_target()
        # The finger leans into the push, so a part of the object at height z above the contact
        # height meets the finger tan(tilt) (z - contact height) later than one at the contact height:
        # the contact point is the first point of the object that the leaning finger meets, not the
        # object's widest part (an overhanging top would put the fingertip in the air beside a thin
        # base and the finger against the top, which tips the object over).
        above = np.maximum(g.vertices_world[:, 2] - self.push_z, 0.0)
        self._lean_setback = above * np.tan(self.tilt_rad)

    @property
    def gripper_closed(self) -> bool:
        return True

    def resume(self, state: str, steps_in_state: int) -> None:
        if state not in ("approaching", "pushing"):
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

    def _support_batch(self, directions_xy: np.ndarray, target_rot: np.ndarray) -> np.ndarray:
        """How far the rotated object reaches from its centre along each horizontal unit direction (m)."""
        directions = np.concatenate([directions_xy, np.zeros(directions_xy.shape[:-1] + (1,))], axis=-1)
        in_target = np.einsum("...ji,...j->...i", target_rot, directions)
        return np.max(in_target @ self._vertices_in_target.T - self._lean_setback, axis=-1)

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

        def score(pos, rot):
            lean = np.arccos(np.clip(np.einsum("...i,...i->...", rot[..., :, 2], axis), -1.0, 1.0))
            value = -w.distance * np.linalg.norm(pos - contact, axis=-1) - w.angle * lean
            scrape = np.maximum(self.geometry.table_height_m + self.clearance_m - pos[..., 2], 0.0)
            value = value - w.height * scrape
            return value if pushing else value - w.height * self.funnel_penalty(pos, contact)

        reward = self.blend(hands, score)
        if pushing:
            reward = self._with_pushing_terms(reward, to_go, speed)
        return reward

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

    def update(self, state: np.ndarray) -> str:
        distance = self._engage_distance(state)
        self.step_count += 1
        if self.state == "approaching" and distance < self.engage_distance_m:
            self.state = "pushing"
        elif self.state == "pushing" and distance > self.disengage_distance_m:
            self.state = "approaching"
        self.near_contact = self.state == "pushing" or distance < self.disengage_distance_m
        return self.state

    def error(self, state: np.ndarray) -> float:
        _, _, target_pos, _ = self.poses(state[None])
        return float(np.linalg.norm(self.goal - target_pos[0]))


def _offsets_along(geometry: TargetGeometry, direction_xy: np.ndarray) -> np.ndarray:
    """Each vertex's offset from the centre of mass along a horizontal unit direction (m)."""
    return (geometry.vertices_world[:, :2] - geometry.com_world[:2]) @ direction_xy


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
    # While pushing, the fingers close to the object's extent along the push plus this each side, and
    # the hand aims this far forward of the cage's middle, so the rear finger presses on the object.
    cage_margin_m: float = 0.003
    press_m: float = 0.01
    # Per radian between the finger closing axis and the push direction.
    cage_yaw: float = 0.5
    # The object may lean this far (rad) into the front finger unpenalised: pushed by the rear finger
    # it leans until the front one holds it.
    cage_tilt_rad: float = 0.3
    # The front finger pushes back an object that slid past the goal in the world but not in the twin.
    push_back_past_goal: bool = True

    def __post_init__(self):
        g = self.geometry
        self.start_com = g.com_world.copy()
        self.goal = g.com_world + self.goal_displacement
        direction = self._direction(g.com_world[None])[0]
        along = _offsets_along(g, direction)
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
        along = _offsets_along(geometry, direction / (np.linalg.norm(direction) + 1e-9))
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
                - w.angle * _angle_down(rot)
                - self.cage_yaw * _yaw_error(rot, direction)
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
