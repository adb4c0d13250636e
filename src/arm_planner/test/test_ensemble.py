"""Twins with perturbed object physics, and MPPI's rollouts spread over them."""

import mujoco
import numpy as np

from arm_planner.ensemble import FRICTION_SCALE, MASS_SCALE, follow_nominal, perturbed_twins
from arm_planner.mppi import STATE_SPEC, BatchedRollout, get_state

SLIDER = """<mujoco><option timestep="0.002"/><worldbody><geom type="plane" size="1 1 0.1" friction="0.3"/>
<body name="box" pos="0 0 0.02"><freejoint/><geom type="box" size="0.02 0.02 0.02" mass="0.1" friction="0.3"/></body>
<body name="arm" pos="0.5 0 0.2"><joint name="slide" type="slide" axis="0 0 1"/><geom size="0.01"/></body>
</worldbody><actuator><position joint="slide" kp="10"/></actuator></mujoco>"""


def test_the_first_twin_is_the_nominal_model_and_the_others_scale_each_object_within_the_ranges():
    model = mujoco.MjModel.from_xml_string(SLIDER)
    box = model.body("box").id
    twins = perturbed_twins(model, np.array([box]), 4, seed=0)
    assert len(twins) == 4 and twins[0] is model and model.body_mass[box] == 0.1
    for twin in twins[1:]:
        assert MASS_SCALE[0] * 0.1 <= twin.body_mass[box] <= MASS_SCALE[1] * 0.1
        friction = twin.geom_friction[twin.geom_bodyid == box, 0]
        assert np.all((FRICTION_SCALE[0] * 0.3 <= friction) & (friction <= FRICTION_SCALE[1] * 0.3))
        assert twin.body_mass[model.body("arm").id] == model.body_mass[model.body("arm").id], "the robot is not scaled"
    assert len({float(t.body_mass[box]) for t in twins}) == 4
    assert perturbed_twins(model, np.array([box]), 4, seed=0)[2].body_mass[box] == twins[2].body_mass[box]


def test_paths_run_in_the_twins_in_turn_and_the_twins_follow_the_nominal_rest_poses():
    model = mujoco.MjModel.from_xml_string(SLIDER)
    box = model.body("box").id
    twins = perturbed_twins(model, np.array([box]), 2, seed=3)
    twins[1].geom_friction[twins[1].geom_bodyid == box, 0] = 0.9  # the box stops sooner there
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    data.qvel[0] = 1.0  # sliding along x at 1 m/s
    state = get_state(model, data)
    rollout = BatchedRollout(model, 0.02, nthread=1, twins=twins)
    states = rollout(state, np.zeros((3, 10, model.nu)), np.zeros(model.nu))
    x_end = states[:, -1, mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_TIME)]
    assert x_end[1] < x_end[0] - 0.01, "path 1 ran in the grippier twin"
    assert x_end[2] == x_end[0], "path 2 ran in the nominal twin again"
    assert states.shape[-1] == mujoco.mj_stateSize(model, STATE_SPEC)
    model.qpos0[0] = 0.3
    follow_nominal(model, twins)
    assert twins[1].qpos0[0] == 0.3
    rollout.close()
