"""Planner behaviour on the small gantry robot: real MPPI over real rollouts, seconds per test."""

import dataclasses

import mujoco
import numpy as np
import pytest
import trimesh
from gantry import GANTRY_SPEC, gantry_model

from arm_core.repeated_runs import holds_repeatedly
from arm_planner.mppi import MppiConfig, get_state
from arm_planner.planner import Planner, PlannerConfig, PlanRequest
from arm_planner.tasks.base import TargetGeometry


def _setup(steps=200, seed=0):
    model = gantry_model()
    model.opt.timestep = 0.01
    config = PlannerConfig(mppi=MppiConfig(steps=steps, nthread=1, seed=seed), realtime_factor=0.0)
    config.noise.linear_std_m_s = 0.3
    config.settle_s = 0.1
    planner = Planner(model, GANTRY_SPEC, config)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    body = model.body("object_0").id
    box = trimesh.creation.box(extents=(0.05, 0.04, 0.06))
    box.apply_translation(data.xpos[body])
    geometry = TargetGeometry(data.xipos[body].copy(), box.vertices, 0.0)
    return planner, get_state(model, data), geometry


@pytest.mark.parametrize(
    "task,displacement",
    [("grasp", (0, 0, 0)), ("push", (0.05, -0.2, 0.0)), ("rearrange", (0.1, 0.1, 0.0))],
)
def test_gantry_plans_meet_each_task_in_simulation_for_most_noise_seeds(task, displacement):
    # MPPI is chaotic: a change that moves a rollout by a micrometre can flip one seed's outcome near
    # the tolerance, so the claim is about several noise seeds (arm_core.repeated_runs), each plan
    # checked in full.
    def attempt(seed):
        planner, state, geometry = _setup(seed=seed)
        result = planner.plan(state, PlanRequest(task, "object_0", np.array(displacement, float)), geometry)
        planner.close()
        assert result.joint_positions.shape == (len(result.times_s), 5)
        assert np.all(np.diff(result.times_s) > 0)
        if task != "push" and result.success:
            order = [s for i, s in enumerate(result.states) if i == 0 or result.states[i - 1] != s]
            assert order == ["ungrasped", "grasping", "grasped"]
            assert result.states.count("grasping") == planner.config.close_steps
        return result.success, result.message

    held, outcomes = holds_repeatedly(attempt)
    assert held, outcomes


def test_plan_respects_actuator_ranges_and_rates():
    planner, state, geometry = _setup(steps=40)
    result = planner.plan(state, PlanRequest("push", "object_0", np.array([0.05, -0.2, 0.0])), geometry)
    limits = planner.limits
    assert np.all(result.controls >= limits.low - 1e-12) and np.all(result.controls <= limits.high + 1e-12)
    arm = planner.robot.arm_actuators
    steps = np.abs(np.diff(result.controls[:, arm], axis=0))
    assert np.all(steps <= limits.max_rate[arm] * planner.config.mppi.control_dt_s + 1e-9)
    planner.close()


def test_push_with_a_hand_speed_cap_meets_the_goal_with_the_hand_no_faster_than_it():
    def attempt(seed):
        planner, state, geometry = _setup(steps=400, seed=seed)
        cap = planner.config.push_hand_speed_m_s = 0.1
        result = planner.plan(state, PlanRequest("push", "object_0", np.array([0.05, -0.2, 0.0])), geometry)
        qpos = np.tile(state[planner.qpos_offset : planner.qpos_offset + planner.model.nq], (len(result.controls), 1))
        qpos[:, planner.robot.qpos_adr] = result.controls[:, planner.robot.arm_actuators]
        commanded_tcp, _ = planner.hand(qpos)
        speed = np.linalg.norm(np.diff(commanded_tcp, axis=0), axis=1) / planner.config.mppi.control_dt_s
        pushing = np.array(result.states[:-1]) == "pushing"  # the state each step was planned in
        planner.close()
        # the cap holds on every run (it is linear in the rates; the arm's path is not, hence 5 %)
        assert pushing.sum() == 0 or speed[pushing].max() <= cap * 1.05
        return result.success and pushing.sum() > 50, result.message

    held, outcomes = holds_repeatedly(attempt)
    assert held, outcomes


def test_unknown_target_body_is_refused():
    planner, state, geometry = _setup(steps=2)
    with pytest.raises(ValueError, match="not in the twin"):
        planner.plan(state, PlanRequest("grasp", "object_7"), geometry)
    with pytest.raises(ValueError, match="unknown task"):
        planner.plan(state, PlanRequest("juggle", "object_0"), geometry)
    planner.close()


def test_realtime_planning_samples_fewer_paths_when_steps_are_slow():
    planner, state, geometry = _setup(steps=30)
    planner.config.realtime_factor = 1e-3  # a budget no step can meet: the fewest paths from the second step
    planner.config.min_paths = 5
    result = planner.plan(state, PlanRequest("push", "object_0", np.array([0.05, -0.2, 0.0])), geometry)
    assert result.step_paths[0] == planner.config.mppi.num_paths
    assert np.all(result.step_paths[1:] == 5) and len(result.step_paths) == len(result.times_s)
    planner.close()
    fixed, state, geometry = _setup(steps=5)
    result = fixed.plan(state, PlanRequest("push", "object_0", np.array([0.05, -0.2, 0.0])), geometry)
    assert np.all(result.step_paths == fixed.config.mppi.num_paths)
    fixed.close()


def test_an_object_at_rest_away_from_where_planning_began_starts_its_rollouts_asleep():
    planner, state, geometry = _setup(steps=2)
    planner.plan(state, PlanRequest("grasp", "object_0", np.zeros(3)), geometry)  # sleeping on, as planned
    model, data = planner.model, planner._data
    tree = int(model.body_treeid[model.body("object_0").id])
    data.qpos[planner._object_qpos[0]] += 0.02  # nudged 2 cm, then left to come to rest
    data.qvel[:] = 0.0
    for _ in range(500):
        mujoco.mj_step(model, data)
        if data.tree_asleep[tree] >= 0:
            break
    assert data.tree_asleep[tree] >= 0

    rollout = planner.mppi.rollout
    still = np.broadcast_to(data.ctrl, (2, 3, model.nu)).copy()

    def asleep_through_rollout() -> bool:
        states = rollout(get_state(model, data), still, data.ctrl.copy())
        moved = np.abs(states[:, -1, 1 + planner._object_qpos[:3]] - data.qpos[planner._object_qpos[:3]]).max()
        return bool(rollout._datas[0].tree_asleep[tree] >= 0 and moved == 0.0)

    assert not asleep_through_rollout()  # away from qpos0, it would start each rollout awake
    planner._sleeping_poses_as_rest(data)
    assert asleep_through_rollout()
    planner.close()


def test_planner_continues_from_an_observed_state():
    """The object is found 3 cm off where the twin had it, 10 steps in: the plan goes on from there."""
    planner, state, geometry = _setup()
    body = planner.model.body("object_0")
    adr = planner.model.jnt_qposadr[body.jntadr[0]]
    calls, seen_x = [], []

    def observe(step, control, model, data):
        calls.append(step)
        seen_x.append(float(data.xipos[body.id][0]))
        if step != 10:
            return False
        data.qpos[adr] += 0.03
        return True

    result = planner.plan(state, PlanRequest("grasp", "object_0"), geometry, observe=observe)
    assert calls == list(range(len(result.times_s)))
    assert abs(seen_x[11] - (geometry.com_world[0] + 0.03)) < 0.002, "the next step starts from the observation"
    assert result.success, result.message
    planner.close()


def test_a_rearrange_that_becomes_a_push_is_planned_as_a_push():
    """A target wider than the open fingers every way is pushed to a rearrange's goal: the push's step
    budget and speed cap, not the rearrange's."""
    _, state, geometry = _setup(steps=2)
    fingers = {
        "finger_gap_open_m": 0.06,
        "fingertip_to_palm_m": 0.06,
        "finger_thickness_m": 0.01,
        "finger_width_m": 0.016,
    }
    config = PlannerConfig(mppi=MppiConfig(steps=2, nthread=1), push_steps=3, rearrange_steps=7)
    planner = Planner(gantry_model(), dataclasses.replace(GANTRY_SPEC, **fingers), config)
    wide = trimesh.creation.box(extents=(0.2, 0.2, 0.06))
    wide.apply_translation(geometry.com_world)
    geometry = TargetGeometry(geometry.com_world, wide.vertices, 0.0)
    result = planner.plan(state, PlanRequest("rearrange", "object_0", np.array([0.1, 0.1, 0.0])), geometry)
    reward = planner._last_reward
    planner.close()
    assert reward.__class__.__name__.endswith("PushReward") and reward.step_budget == 3 == len(result.times_s)
    assert reward.push_speed_m_s == planner.config.push_hand_speed_m_s > 0
    assert reward.hand_speed_cap_m_s() == (reward.push_speed_m_s if reward.near_contact else 0.0)
