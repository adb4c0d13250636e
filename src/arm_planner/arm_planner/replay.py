"""A finished plan replayed open loop in twins a little different from the one it was made in.

A plan meets the task in the twin it was planned in; on the robot the object lies a few millimetres
from its reconstruction, its friction and mass are unknown, the controllers start late and the
encoders are off. Each of `perturbed_twins` copies of the twin gets one draw of those differences (the
ranges of bench_manip's robust worlds): every object moved by up to shift_m in x and y and turned by
up to turn_deg about the vertical, its sliding friction and mass scaled, the plan's controls up to
latency_steps control steps late, and every arm joint off by up to joint_offset_deg (a commanded angle
lands that far off). The plan's controls are replayed in all of them in one batched rollout; the
share that still meets the task tells a plan with room to spare from one that only works in the twin
exactly as it was (the demo prefers the former among its dry runs).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import mujoco.rollout
import numpy as np

from arm_core.settings import setting
from arm_planner.mppi import ramp_controls, state_layout

# Whether a twin state vector (mppi.STATE_SPEC) at a replay's end meets the task.
Meets = Callable[[np.ndarray], bool]


@dataclass(frozen=True)
class ReplayConfig:
    perturbed_twins: int = setting(5, "Perturbed twins each plan made without feedback is replayed in (0: none)", 0, 64)
    shift_m: float = setting(0.005, "Replay: objects moved by up to this in x and y, m", 0.0, 0.1)
    turn_deg: float = setting(5.0, "Replay: objects turned by up to this about the vertical, degrees", 0.0, 45.0)
    friction_spread: float = setting(0.5, "Replay: sliding friction scaled by 1 +- this", 0.0, 0.9)
    mass_spread: float = setting(0.3, "Replay: masses scaled by 1 +- this", 0.0, 0.9)
    latency_steps: int = setting(2, "Replay: the controls up to this many control steps late", 0, 50)
    joint_offset_deg: float = setting(0.5, "Replay: arm joints off by up to this, degrees", 0.0, 5.0)
    perturbation_seed: int = setting(0, "Replay: seed of the perturbations", 0, 2**31 - 1)


@dataclass(frozen=True)
class ReplayOutcome:
    twins: int
    met: int

    @property
    def share(self) -> float:
        return self.met / self.twins if self.twins else 0.0


def _free_joints(model: mujoco.MjModel) -> np.ndarray:
    return np.flatnonzero(model.jnt_type == mujoco.mjtJoint.mjJNT_FREE)


def perturbed_model(model: mujoco.MjModel, friction_scales: np.ndarray, mass_scales: np.ndarray) -> mujoco.MjModel:
    """A copy of model with sleeping off (a rollout then starts every body from the given state, not
    from qpos0) and each free body's sliding friction and mass (and inertia) scaled, in the order of
    its free joint."""
    moved = copy.copy(model)
    moved.opt.enableflags &= ~int(mujoco.mjtEnableBit.mjENBL_SLEEP)
    for joint, friction, mass in zip(_free_joints(model), friction_scales, mass_scales, strict=True):
        body = int(model.jnt_bodyid[joint])
        moved.geom_friction[model.geom_bodyid == body, 0] *= friction
        moved.body_mass[body] *= mass
        moved.body_inertia[body] *= mass
    return moved


def _turned_about_vertical(quat_wxyz: np.ndarray, angle_rad: float) -> np.ndarray:
    turn = np.array([np.cos(angle_rad / 2), 0.0, 0.0, np.sin(angle_rad / 2)])
    out = np.empty(4)
    mujoco.mju_mulQuat(out, turn, quat_wxyz)
    return out


def perturbed_state(
    model: mujoco.MjModel, state: np.ndarray, shifts_m: np.ndarray, turns_rad: np.ndarray, arm_qpos_adr, offsets_rad
) -> np.ndarray:
    """The twin state vector (STATE_SPEC) with each free body shifted in x and y (shifts_m (n, 2)) and
    turned about the vertical through its origin (turns_rad (n,)), and the arm joints moved by
    offsets_rad."""
    out = np.array(state, dtype=np.float64)
    qpos = state_layout(model)[0]
    for joint, shift, angle in zip(_free_joints(model), shifts_m, turns_rad, strict=True):
        adr = qpos + int(model.jnt_qposadr[joint])
        out[adr : adr + 2] += shift
        out[adr + 3 : adr + 7] = _turned_about_vertical(out[adr + 3 : adr + 7], float(angle))
    out[qpos + np.asarray(arm_qpos_adr, dtype=int)] += offsets_rad
    return out


def replay_in_perturbed_twins(
    model: mujoco.MjModel,
    initial_state: np.ndarray,
    initial_ctrl: np.ndarray,
    controls: np.ndarray,
    substeps: int,
    settle_steps: int,
    arm_qpos_adr,
    arm_actuators,
    meets: Meets,
    config: ReplayConfig,
) -> ReplayOutcome:
    """Replay a plan's controls (N control steps, nu) open loop in config.perturbed_twins perturbed copies
    of the twin `model`, from the plan's initial state (before its settling) with initial_ctrl held for
    settle_steps physics steps, each control step ramped over `substeps` physics steps from the one
    before (as the planner executes them); `meets` judges each replay's final state."""
    controls = np.asarray(controls, dtype=np.float64)
    if config.perturbed_twins <= 0 or len(controls) == 0:
        return ReplayOutcome(0, 0)
    rng = np.random.default_rng(config.perturbation_seed)
    n_objects, n_arm = len(_free_joints(model)), len(arm_actuators)
    turn, offset = np.deg2rad(config.turn_deg), np.deg2rad(config.joint_offset_deg)
    models, states, ctrls = [], [], []
    for _ in range(config.perturbed_twins):
        friction = 1.0 + rng.uniform(-config.friction_spread, config.friction_spread, n_objects)
        mass = 1.0 + rng.uniform(-config.mass_spread, config.mass_spread, n_objects)
        shifts = rng.uniform(-config.shift_m, config.shift_m, (n_objects, 2))
        turns = rng.uniform(-turn, turn, n_objects)
        offsets = rng.uniform(-offset, offset, n_arm)
        late = int(rng.integers(0, config.latency_steps + 1))
        models.append(perturbed_model(model, friction, mass))
        states.append(perturbed_state(model, initial_state, shifts, turns, arm_qpos_adr, offsets))
        ctrls.append(
            physics_step_controls(
                initial_ctrl, controls, substeps, settle_steps, late, config.latency_steps, arm_actuators, offsets
            )
        )
    runner = mujoco.rollout.Rollout(nthread=0)
    try:
        states_out, _ = runner.rollout(
            models, mujoco.MjData(model), np.stack(states), np.stack(ctrls), control_spec=mujoco.mjtState.mjSTATE_CTRL
        )
    finally:
        runner.close()
    final = states_out[:, -1]
    return ReplayOutcome(config.perturbed_twins, sum(bool(meets(s)) for s in final))


def physics_step_controls(
    initial_ctrl, controls, substeps: int, settle_steps: int, late_steps: int, max_late_steps: int, arm_actuators,
    offsets_rad,
) -> np.ndarray:  # fmt: skip
    """(settle_steps + (max_late_steps + N) * substeps, nu) targets per physics step: initial_ctrl while
    the twin settles and for late_steps control steps more, then each control step ramped linearly from
    the one before, then the last held; the arm's targets moved by offsets_rad."""
    initial_ctrl = np.asarray(initial_ctrl, dtype=np.float64)
    held = [np.repeat(initial_ctrl[None], late_steps, axis=0), controls]
    held.append(np.repeat(controls[-1:], max_late_steps - late_steps, axis=0))
    ramp = ramp_controls(initial_ctrl, np.vstack(held)[None], substeps)[0]
    out = np.vstack([np.repeat(initial_ctrl[None], settle_steps, axis=0), ramp])
    out[:, np.asarray(arm_actuators, dtype=int)] += offsets_rad
    return out
