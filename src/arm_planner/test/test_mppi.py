import mujoco
import numpy as np
import pytest
from gantry import gantry_model

from arm_planner.mppi import (
    BatchedRollout,
    ControlLimits,
    Mppi,
    MppiConfig,
    PathBudget,
    free_body_trees,
    get_state,
    linear_speed_cap,
    set_sleep,
    state_layout,
)


def test_integrated_targets_respect_box_and_rate_limits():
    limits = ControlLimits(np.array([-1.0, 0.0]), np.array([1.0, 0.04]), np.array([2.0, 0.1]))
    rates = np.random.default_rng(0).normal(scale=10.0, size=(50, 5, 2))
    targets = limits.integrate(np.array([0.9, 0.0]), rates, 0.02)
    assert np.all(targets >= limits.low) and np.all(targets <= limits.high)
    steps = np.abs(np.diff(np.concatenate([np.broadcast_to([0.9, 0.0], (50, 1, 2)), targets], axis=1), axis=1))
    assert np.all(steps <= limits.max_rate * 0.02 + 1e-12)


def test_limits_come_from_actuator_and_joint_ranges():
    model = gantry_model()
    limits = ControlLimits.from_model(model, 0.5)
    np.testing.assert_allclose(limits.low[:3], [-0.5, -0.5, -0.29])
    np.testing.assert_allclose(limits.high[4], 0.04)


def test_noise_is_smooth_and_path_zero_is_the_nominal():
    model = gantry_model()
    mppi = Mppi(
        model,
        MppiConfig(num_paths=400, horizon=5, noise_smoothing=0.9, nthread=0),
        ControlLimits.from_model(model, 1.0),
    )
    noise = mppi.sample_noise(np.eye(model.nu))
    assert noise.shape == (400, 5, model.nu)
    assert np.all(noise[0] == 0)
    lag1 = np.corrcoef(noise[1:, :-1, 0].ravel(), noise[1:, 1:, 0].ravel())[0, 1]
    assert 0.8 < lag1 < 0.97
    assert 0.8 < noise[1:].std() < 1.2
    mppi.close()


def test_batched_rollout_equals_stepping_one_by_one():
    model = gantry_model()
    model.opt.timestep = 0.01
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    state = get_state(model, data)
    rng = np.random.default_rng(3)
    controls = data.ctrl + rng.normal(scale=0.05, size=(4, 3, model.nu))
    previous = data.ctrl.copy()
    rollout = BatchedRollout(model, 0.02, nthread=2)
    states = rollout(state, controls, previous)
    assert states.shape == (4, 3, state.size)
    qpos_offset, _ = state_layout(model)
    for path in range(4):
        fresh = mujoco.MjData(model)
        mujoco.mj_setState(model, fresh, state, mujoco.mjtState.mjSTATE_FULLPHYSICS)
        data = fresh
        for k, target in enumerate(rollout.substep_controls(previous, controls[path : path + 1])[0]):
            data.ctrl[:] = target
            mujoco.mj_step(model, data)
            if (k + 1) % rollout.substeps == 0:
                np.testing.assert_allclose(
                    states[path, k // rollout.substeps, qpos_offset : qpos_offset + model.nq], data.qpos, atol=1e-6
                )
    rollout.close()


def test_mppi_steers_the_gantry_to_a_point():
    model = gantry_model()
    model.opt.timestep = 0.01
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    hand = model.body("hand").id
    goal = np.array([0.2, -0.1, 0.25])
    qpos_offset, _ = state_layout(model)

    def reward(states, controls):
        qpos = states[..., qpos_offset : qpos_offset + model.nq]
        hand_xyz = np.stack([qpos[..., 0], qpos[..., 1], 0.3 + qpos[..., 2]], axis=-1)
        return -np.linalg.norm(hand_xyz - goal, axis=-1)

    limits = ControlLimits.from_model(model, 0.5)
    mppi = Mppi(model, MppiConfig(nthread=1, seed=1), limits)
    mppi.reset()
    control = data.ctrl.copy()
    basis = np.zeros((3, model.nu))
    basis[[0, 1, 2], [0, 1, 2]] = 0.3
    start = np.linalg.norm(data.xpos[hand] - goal)
    for _ in range(60):
        result = mppi.step(get_state(model, data), control, reward, basis)
        for target in mppi.rollout.substep_controls(control, result.control[None, None])[0]:
            data.ctrl[:] = target
            mujoco.mj_step(model, data)
        control = result.control
        mppi.shift()
    mujoco.mj_forward(model, data)
    assert np.linalg.norm(data.xpos[hand] - goal) < 0.1 * start
    mppi.close()


def test_speed_cap_scales_only_fast_steps_and_keeps_averages_capped():
    jac = np.array([[1.0, 0.0], [0.0, 2.0], [0.0, 0.0]])  # two actuators -> x, y (m/s per unit rate)
    cap = linear_speed_cap(jac, np.array([0, 2]), 0.1)
    rates = np.zeros((50, 4, 3))
    rates[..., [0, 2]] = np.random.default_rng(0).normal(0.0, 0.2, (50, 4, 2))
    rates[0, 0, [0, 2]] = [0.01, 0.02]  # 0.041 m/s: under the cap
    rates[..., 1] = 7.0  # not a capped actuator
    capped = cap(rates)
    speed = np.linalg.norm(capped[..., [0, 2]] @ jac.T, axis=-1)
    assert speed.max() <= 0.1 + 1e-12
    np.testing.assert_allclose(capped[0, 0], rates[0, 0])
    np.testing.assert_array_equal(capped[..., 1], 7.0)
    before = np.linalg.norm(rates[..., [0, 2]] @ jac.T, axis=-1)
    np.testing.assert_allclose(speed[before > 0.1], 0.1)
    average = np.einsum("n,nhu->hu", np.full(50, 1 / 50), capped)
    assert np.linalg.norm(average[:, [0, 2]] @ jac.T, axis=-1).max() <= 0.1 + 1e-12


def test_mppi_with_a_speed_cap_moves_the_gantry_no_faster_than_it():
    model = gantry_model()
    model.opt.timestep = 0.01
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    qpos_offset, _ = state_layout(model)
    goal = np.array([0.3, 0.0, 0.0])

    def reward(states, controls):
        return -np.linalg.norm(states[..., qpos_offset : qpos_offset + 3] - goal, axis=-1)

    mppi = Mppi(model, MppiConfig(nthread=1, seed=1), ControlLimits.from_model(model, 0.5))
    basis = np.zeros((3, model.nu))
    basis[[0, 1, 2], [0, 1, 2]] = 0.3
    cap = linear_speed_cap(np.eye(3), np.arange(3), 0.05)
    control, start = data.ctrl.copy(), data.qpos[:3].copy()
    for _ in range(40):
        result = mppi.step(get_state(model, data), control, reward, basis, rate_filter=cap)
        assert np.linalg.norm(result.control[:3] - control[:3]) <= 0.05 * mppi.config.control_dt_s + 1e-9
        for target in mppi.rollout.substep_controls(control, result.control[None, None])[0]:
            data.ctrl[:] = target
            mujoco.mj_step(model, data)
        control = result.control
        mppi.shift()
    moved = np.linalg.norm(data.qpos[:3] - start)
    assert 0.02 < moved <= 0.05 * 40 * mppi.config.control_dt_s + 0.005
    mppi.close()


def test_non_finite_returns_get_no_weight():
    model = gantry_model()
    model.opt.timestep = 0.01
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    mppi = Mppi(model, MppiConfig(nthread=0), ControlLimits.from_model(model, 0.5))
    calls = []

    def reward(states, controls):
        r = np.zeros(states.shape[:2])
        r[1] = np.nan
        calls.append(1)
        return r

    result = mppi.step(get_state(model, data), data.ctrl.copy(), reward, 0.1 * np.eye(model.nu))
    assert result.weights[1] == 0 and np.isclose(result.weights.sum(), 1.0)
    assert np.all(np.isfinite(result.control))
    mppi.close()


def test_with_sleep_each_path_is_independent_of_the_paths_before_it():
    model = gantry_model()
    model.opt.timestep = 0.01
    data = mujoco.MjData(model)
    hand_beside_object = {"gx": 0.09, "gz": -0.22}
    for name, value in hand_beside_object.items():
        data.qpos[model.joint(name).qposadr[0]] = value
        data.ctrl[model.actuator("a" + name[1:]).id] = value
    mujoco.mj_step(model, data, nstep=200)
    set_sleep(model, free_body_trees(model), start_asleep=True)
    data.qvel[:] = 0.0
    data.qpos[model.jnt_qposadr[model.body("object_0").jntadr[0]] + 2] -= 0.001  # not at rest: awake, it moves
    state = get_state(model, data)
    push, stay = data.ctrl.copy(), data.ctrl.copy()
    push[model.actuator("ax").id] += 0.1
    controls = np.stack([np.broadcast_to(push, (5, model.nu)), np.broadcast_to(stay, (5, model.nu))])
    object_x = state_layout(model)[0] + model.jnt_qposadr[model.body("object_0").jntadr[0]]
    for nthread in (0, 2):
        rollout = BatchedRollout(model, 0.02, nthread)
        batch = rollout(state, controls, data.ctrl.copy()).copy()
        assert batch[0, -1, object_x] - state[object_x] > 0.005  # the first path pushed the object
        alone = rollout(state, controls[1:], data.ctrl.copy())
        np.testing.assert_array_equal(batch[1], alone[0])
        rollout.close()


def test_path_budget_fits_the_paths_into_the_step_time():
    budget = PathBudget(max_paths=25, min_paths=8, realtime_factor=1.0, control_dt_s=0.02, smoothing=1.0)
    assert budget.paths == 25
    assert budget.update(25, 0.040) == 12  # 1.6 ms a path: 12 fit into 20 ms
    assert budget.update(12, 0.012) == 20  # 1 ms a path
    assert budget.update(20, 0.200) == 8  # never below min_paths
    assert budget.update(8, 0.001) == 25  # never above max_paths
    averaged = PathBudget(25, 2, 1.0, 0.02, smoothing=0.5)
    averaged.update(10, 0.010)
    assert averaged.update(10, 0.030) == 10  # mean of 1 and 3 ms a path: 2 ms
    with pytest.raises(ValueError):
        PathBudget(25, 30, 1.0, 0.02)
