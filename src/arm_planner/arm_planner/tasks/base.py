"""What every task reward shares: the target's geometry at planning start, the reward weights, the
hand and target poses from batched states, and the hand-angle terms."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from arm_planner.kinematics import BodyKinematics


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
    # The target's own convex parts, the same way (empty: unknown).
    part_halfspaces: list = field(default_factory=list)
    # Points spread over the target's surface, world frame (metres); empty: its vertices stand for it.
    surface_points_world: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def vertices_in_target(self) -> np.ndarray:
        """Vertices relative to the centre of mass, in the target body's frame (metres)."""
        return (self.vertices_world - self.com_world) @ np.asarray(self.R_world_target, dtype=np.float64)

    def surface_points(self) -> np.ndarray:
        """The vertices and the surface points, world frame (metres)."""
        return np.concatenate([self.vertices_world, np.asarray(self.surface_points_world).reshape(-1, 3)])

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


def angle_down(rot: np.ndarray) -> np.ndarray:
    """Angle between the hand's approach axis (its z axis) and world -z, radians."""
    return np.arccos(np.clip(-rot[..., 2, 2], -1.0, 1.0))


def tilt_beyond(rot: np.ndarray, free_rad: float) -> np.ndarray:
    """How far (radians) the hand's approach axis tilts from world -z beyond free_rad; 0 within it."""
    return np.maximum(angle_down(rot) - free_rad, 0.0)


def yaw_error(rot: np.ndarray, axis_xy: np.ndarray) -> np.ndarray:
    """Angle between the finger closing axis (hand y) and a horizontal axis, modulo pi."""
    fingers = rot[..., :2, 1]
    norm = np.linalg.norm(fingers, axis=-1) + 1e-9
    along = np.abs(np.sum(fingers * np.asarray(axis_xy)[..., :2], axis=-1))
    return np.arccos(np.clip(along / norm, 0.0, 1.0))


class TaskInfeasible(ValueError):
    """The robot cannot do the task at all (the gripper cannot hold the target), whatever the plan."""


@dataclass
class TaskSetup:
    """What a task's reward is built from (tasks.registry): the keyword arguments every reward takes,
    the planner's settings (PlannerConfig), the robot (RobotSpec), its open fingers (None: not used)
    and the state index of the target's velocity (None: not a free body)."""

    common: dict
    config: object
    robot: object
    fingers: object = None
    target_vel_adr: int | None = None

    def step_budget(self, own_steps: int) -> int:
        """The task's own step budget, or the planner's `steps` when that is 0."""
        return int(own_steps or self.config.mppi.steps)


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
    # MPPI steps the task may take (set by the task's builder in tasks.registry).
    step_budget: int = 200

    # The planner's loop asks the task, never its name: its step budget, the hand's speed cap now,
    # whether its goal can be held now (the loop stops once it held a while) and whether it is met.
    def hand_speed_cap_m_s(self) -> float:
        """The hand's top speed for the next step, m/s (0: no cap)."""
        return 0.0

    def holds_goal(self) -> bool:
        """Whether the task is in a state that keeps its goal once reached (an early stop may end it)."""
        return True

    def met(self, com_world: np.ndarray, tolerance_m: float) -> tuple[bool, float]:
        """(met, error m) with the target's centre of mass at com_world: within tolerance of the goal."""
        error = float(np.linalg.norm(self.goal - com_world))
        return error <= tolerance_m, error

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


def narrowest_horizontal_width_m(vertices_world: np.ndarray, directions: int = 12) -> float:
    """A vertex set's least horizontal width (world metres) over `directions` directions across half a
    turn: what a parallel gripper closing horizontally must span at the least."""
    angles = np.pi * np.arange(directions) / directions
    axes = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    return float(np.ptp(np.asarray(vertices_world)[:, :2] @ axes.T, axis=0).min())


def offsets_along(geometry: TargetGeometry, direction_xy: np.ndarray) -> np.ndarray:
    """Each vertex's offset from the centre of mass along a horizontal unit direction (m)."""
    return (geometry.vertices_world[:, :2] - geometry.com_world[:2]) @ direction_xy
