"""Worlds a little different from the one a plan was made for, as a real robot meets them.

A plan made in a twin of the view is executed again in K perturbed copies of the ground-truth world:
each object moved by up to `shift_m` and turned about the vertical by up to `turn_deg`, its sliding
friction and mass scaled, the controller `latency_s` late, and the robot's joints off by up to
`joint_offset_deg` (its encoders: every commanded position lands that far off). The share of those
executions that still meet the task is the plan's robust success.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from arm_planner.mppi import MppiConfig
from arm_planner.replay import ReplayConfig
from arm_sim import robot
from arm_sim.world import SimWorld

SETTLE_S = 0.3  # objects moved into a neighbour come apart before the robot moves


# The planner's own perturbed twins (arm_planner.replay) draw from the same ranges.
_REPLAY = ReplayConfig()
_CONTROL_DT_S = MppiConfig().control_dt_s


@dataclass(frozen=True)
class WorldPerturbation:
    """Ranges of the perturbations (each drawn uniformly)."""

    shift_m: float = _REPLAY.shift_m
    turn_deg: float = _REPLAY.turn_deg
    friction_scale: tuple[float, float] = (1.0 - _REPLAY.friction_spread, 1.0 + _REPLAY.friction_spread)
    mass_scale: tuple[float, float] = (1.0 - _REPLAY.mass_spread, 1.0 + _REPLAY.mass_spread)
    latency_s: tuple[float, float] = (0.0, _REPLAY.latency_steps * _CONTROL_DT_S)
    joint_offset_deg: float = _REPLAY.joint_offset_deg


@dataclass(frozen=True)
class PerturbedDraw:
    """One draw of WorldPerturbation for a scene of n objects."""

    shifts_m: np.ndarray  # (n, 2) xy
    turns_rad: np.ndarray  # (n,) about the vertical
    friction_scales: np.ndarray  # (n,)
    mass_scales: np.ndarray  # (n,)
    latency_s: float
    joint_offsets_rad: np.ndarray  # (7,)


def draw(spec: WorldPerturbation, n_objects: int, rng: np.random.Generator) -> PerturbedDraw:
    turn, offset = np.deg2rad(spec.turn_deg), np.deg2rad(spec.joint_offset_deg)
    return PerturbedDraw(
        shifts_m=rng.uniform(-spec.shift_m, spec.shift_m, (n_objects, 2)),
        turns_rad=rng.uniform(-turn, turn, n_objects),
        friction_scales=rng.uniform(*spec.friction_scale, n_objects),
        mass_scales=rng.uniform(*spec.mass_scale, n_objects),
        latency_s=float(rng.uniform(*spec.latency_s)),
        joint_offsets_rad=rng.uniform(-offset, offset, len(robot.JOINT_NAMES)),
    )


def moved_poses(poses: list[np.ndarray], shifts_m: np.ndarray, turns_rad: np.ndarray) -> list[np.ndarray]:
    """Object poses (4x4, world) turned about the vertical through their origin and shifted in xy."""
    out = []
    for T, shift, angle in zip(poses, shifts_m, turns_rad, strict=True):
        c, s = np.cos(angle), np.sin(angle)
        moved = T.copy()
        moved[:3, :3] = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ T[:3, :3]
        moved[:2, 3] += shift
        out.append(moved)
    return out


def perturbed_world(scene, sample: PerturbedDraw) -> SimWorld:
    """The scene's world with the draw applied (robot at home plus its joint offsets, objects settled)."""
    poses = moved_poses([o.T_world_object for o in scene.objects], sample.shifts_m, sample.turns_rad)
    world = SimWorld(scene.with_poses(poses), robot_arm=True)
    model = world.model
    for k, body in enumerate(world.object_ids):
        geoms = np.flatnonzero(model.geom_bodyid == body)
        model.geom_friction[geoms, 0] *= sample.friction_scales[k]
        model.body_mass[body] *= sample.mass_scales[k]
        model.body_inertia[body] *= sample.mass_scales[k]
    world.set_robot_state(robot.HOME_Q + sample.joint_offsets_rad, robot.GRIPPER_OPEN_M)
    world.settle(SETTLE_S)
    return world


def execute_perturbed(world: SimWorld, times_s: np.ndarray, positions: np.ndarray, sample: PerturbedDraw) -> None:
    """Execute a planned trajectory (times s, positions (N, 8)) as the perturbed robot does: late by
    the draw's latency, every arm joint landing off by its offset."""
    late = np.asarray(times_s, dtype=np.float64) + sample.latency_s
    commanded = np.asarray(positions, dtype=np.float64).copy()
    commanded[:, : len(robot.JOINT_NAMES)] += sample.joint_offsets_rad
    world.execute(late, commanded)
