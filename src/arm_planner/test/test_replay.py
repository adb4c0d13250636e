"""Plans replayed open loop in perturbed twins (arm_planner.replay) on the small gantry robot."""

import dataclasses

import mujoco
import numpy as np
from test_planner import _setup

from arm_core.repeated_runs import holds_repeatedly
from arm_planner.mppi import state_layout
from arm_planner.planner import PlanRequest
from arm_planner.replay import ReplayConfig, perturbed_model, perturbed_state, physics_step_controls

UNPERTURBED = ReplayConfig(
    perturbed_twins=3,
    shift_m=0.0,
    turn_deg=0.0,
    friction_spread=0.0,
    mass_spread=0.0,
    latency_steps=0,
    joint_offset_deg=0.0,
)


def _grasp(seed: int, replay: ReplayConfig):
    planner, state, geometry = _setup(seed=seed)
    planner.config = dataclasses.replace(planner.config, replay=replay)
    result = planner.plan(state, PlanRequest("grasp", "object_0", np.zeros(3)), geometry)
    planner.close()
    return result


def test_a_plan_that_met_the_task_meets_it_in_every_unperturbed_replay():
    def attempt(seed):
        result = _grasp(seed, UNPERTURBED)
        if not result.success:
            return False, result.message
        return result.replays.met == result.replays.twins == 3, f"{result.replays} {result.message}"

    held, outcomes = holds_repeatedly(attempt)
    assert held, outcomes
    assert "of 3 perturbed twins" in next(detail for ok, detail in outcomes if ok)


def test_objects_moved_further_than_the_fingers_reach_fail_the_replays():
    far = dataclasses.replace(UNPERTURBED, perturbed_twins=4, shift_m=0.2, perturbation_seed=3)

    def attempt(seed):
        result = _grasp(seed, far)
        return result.success and result.replays.twins == 4 and result.replays.met <= 1, str(result.replays)

    held, outcomes = holds_repeatedly(attempt)
    assert held, outcomes


def test_a_plan_that_did_not_meet_the_task_or_twins_zero_is_not_replayed():
    result = _grasp(0, dataclasses.replace(UNPERTURBED, perturbed_twins=0))
    assert result.replays.twins == 0 and result.replays.share == 0.0


def test_perturbed_state_moves_and_turns_each_object_about_the_vertical_and_offsets_the_arm():
    planner, state, _ = _setup()
    model = planner.model
    planner.close()
    qpos = state_layout(model)[0]
    free = np.flatnonzero(model.jnt_type == mujoco.mjtJoint.mjJNT_FREE)
    adr = qpos + int(model.jnt_qposadr[free[0]])
    shifts, turns = np.tile([[0.003, -0.004]], (len(free), 1)), np.full(len(free), np.pi / 2)
    arm = np.array([0, 1])
    moved = perturbed_state(model, state, shifts, turns, arm, np.array([0.01, -0.02]))
    assert np.allclose(moved[adr : adr + 3] - state[adr : adr + 3], [0.003, -0.004, 0.0])
    data = mujoco.MjData(model)
    mujoco.mj_setState(model, data, moved, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    mujoco.mj_kinematics(model, data)
    before = mujoco.MjData(model)
    mujoco.mj_setState(model, before, state, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    mujoco.mj_kinematics(model, before)
    body = int(model.jnt_bodyid[free[0]])
    turned = data.xmat[body].reshape(3, 3) @ before.xmat[body].reshape(3, 3).T
    assert np.allclose(turned, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-9), "a quarter turn about +z"
    assert np.allclose(moved[qpos + arm] - state[qpos + arm], [0.01, -0.02])


def test_physics_step_controls_settle_wait_ramp_and_hold_with_the_arm_offsets():
    initial = np.array([0.0, 0.0, 1.0])
    controls = np.array([[1.0, 2.0, 1.0], [3.0, 4.0, 1.0]])
    out = physics_step_controls(initial, controls, 2, 3, 1, 2, np.array([0, 1]), np.array([0.5, 0.0]))
    assert out.shape == (3 + (2 + 2) * 2, 3)
    assert np.allclose(out[:5, :2], [[0.5, 0.0]] * 5), "settling, then one control step late"
    assert np.allclose(out[5:9, :2], [[1.0, 1.0], [1.5, 2.0], [2.5, 3.0], [3.5, 4.0]]), "ramped, offset"
    assert np.allclose(out[9:, :2], [[3.5, 4.0]] * 2), "the last held to the common length"


def test_perturbed_model_scales_friction_and_mass_of_the_free_bodies_only_and_sleeps_never():
    planner, _, _ = _setup()
    model = planner.model
    planner.close()
    model.opt.enableflags |= int(mujoco.mjtEnableBit.mjENBL_SLEEP)
    free = np.flatnonzero(model.jnt_type == mujoco.mjtJoint.mjJNT_FREE)
    body = int(model.jnt_bodyid[free[0]])
    moved = perturbed_model(model, np.full(len(free), 1.5), np.full(len(free), 0.5))
    geoms = model.geom_bodyid == body
    assert np.allclose(moved.geom_friction[geoms, 0], 1.5 * model.geom_friction[geoms, 0])
    assert np.allclose(moved.geom_friction[~geoms], model.geom_friction[~geoms])
    assert np.isclose(moved.body_mass[body], 0.5 * model.body_mass[body])
    assert not moved.opt.enableflags & int(mujoco.mjtEnableBit.mjENBL_SLEEP)
    assert model.opt.enableflags & int(mujoco.mjtEnableBit.mjENBL_SLEEP), "the twin itself is unchanged"
