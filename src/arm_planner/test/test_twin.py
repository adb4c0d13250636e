import mujoco
import numpy as np
import pytest
import trimesh

from arm_planner.finger_clearance import clearance_m
from arm_planner.mppi import STATE_SPEC
from arm_planner.twin import Twin, TwinError, TwinObject, geometry_signature, stabilize_servos, usable_parts
from arm_sim import robot


def _box_object(object_id, xyz, extents=(0.05, 0.05, 0.08), parts=True):
    box = trimesh.creation.box(extents=extents)
    T = np.eye(4)
    T[:3, 3] = xyz
    return TwinObject(object_id, T, box, [box.copy()] if parts else [])


def test_twin_maps_ids_to_bodies_and_targets():
    twin = Twin([_box_object(3, (0.0, 0.0, 0.04)), _box_object(5, (0.1, 0.1, 0.04))], 0.0, 0.01)
    assert 3 in twin and 5 in twin and 4 not in twin
    geometry = twin.target_geometry(5)
    np.testing.assert_allclose(geometry.com_world, [0.1, 0.1, 0.04], atol=1e-9)
    assert geometry.top_z == pytest.approx(0.08)
    assert twin.model.opt.timestep == 0.01
    # The other object is an obstacle, at the pose given (moved 0.3 m up here) or as built.
    assert geometry.obstacle_vertices_world[:, :2].mean(axis=0) == pytest.approx([0.0, 0.0], abs=1e-9)
    T_up = np.eye(4)
    T_up[:3, 3] = (0.0, 0.0, 0.34)
    moved = twin.target_geometry(5, {3: T_up})
    assert moved.obstacle_vertices_world[:, 2].min() == pytest.approx(0.30)
    # ... and its convex parts as half-spaces, where it stands.
    assert clearance_m(np.array([[0.0, 0.0, 0.34]]), moved.obstacle_halfspaces) == pytest.approx(-0.025)
    assert clearance_m(np.array([[0.0, 0.0, 0.04]]), moved.obstacle_halfspaces) == pytest.approx(0.26)


def test_degenerate_objects_are_skipped_with_a_reason():
    flat = TwinObject(2, np.eye(4), trimesh.Trimesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]]), [[0, 1, 2]]), [])
    bad_pose = _box_object(4, (0, 0, 0))
    bad_pose.T_world_object[0, 0] = np.nan
    twin = Twin([_box_object(1, (0, 0, 0.04)), flat, bad_pose], 0.0, 0.01)
    assert 1 in twin and 2 not in twin and 4 not in twin
    assert "degenerate" in twin.skipped[2] and "finite" in twin.skipped[4]


def test_objects_without_parts_are_decomposed():
    open_box = trimesh.creation.box(extents=(0.05, 0.05, 0.08))
    open_box.update_faces(np.arange(len(open_box.faces)) != 0)  # not watertight: convex hull fallback
    parts = usable_parts(TwinObject(1, np.eye(4), open_box, []))
    assert len(parts) == 1 and parts[0].volume == pytest.approx(0.05 * 0.05 * 0.08, rel=1e-6)


def test_signature_ignores_poses_but_not_geometry():
    a = [_box_object(1, (0, 0, 0.04))]
    b = [_box_object(1, (0.2, 0, 0.04))]
    c = [_box_object(1, (0, 0, 0.04), extents=(0.06, 0.05, 0.08))]
    assert geometry_signature(a, 0.0) == geometry_signature(b, 0.0) != geometry_signature(c, 0.0)


def test_initial_state_places_robot_and_objects():
    twin = Twin([_box_object(1, (0, 0, 0.04))], 0.0, 0.01)
    T = np.eye(4)
    T[:3, 3] = (0.05, -0.05, 0.04)
    state = twin.initial_state(robot.HOME_Q, 0.02, {1: T})
    data = mujoco.MjData(twin.model)
    mujoco.mj_setState(twin.model, data, state, STATE_SPEC)
    mujoco.mj_forward(twin.model, data)
    np.testing.assert_allclose(data.xpos[twin.model.body(twin.body_name(1)).id], T[:3, 3], atol=1e-12)
    np.testing.assert_allclose(data.qpos[twin.robot.resolve(twin.model).qpos_adr], robot.HOME_Q)


def test_non_finite_table_is_a_twin_error():
    with pytest.raises(TwinError):
        Twin([], float("nan"))


def test_servo_stabilisation_bounds_step_times_frequency():
    twin = Twin([], 0.0, 0.02)
    model = twin.model
    for a in range(model.nu):
        dof = model.jnt_dofadr[model.actuator_trnid[a, 0]]
        assert np.sqrt(model.actuator_gainprm[a, 0] / model.dof_armature[dof]) * 0.02 <= 0.5 + 1e-9
    before = model.dof_armature.copy()
    stabilize_servos(model)
    np.testing.assert_array_equal(before, model.dof_armature)


def _contacts_between(model, data, body_a: str, body_b: str) -> int:
    a, b = model.body(body_a).id, model.body(body_b).id
    pairs = {frozenset((model.geom_bodyid[c.geom1], model.geom_bodyid[c.geom2])) for c in data.contact[: data.ncon]}
    return int(frozenset((a, b)) in pairs)


def test_objects_overlapping_as_built_pass_through_each_other_and_touching_ones_collide():
    overlapping = [_box_object(1, (0.0, 0.0, 0.04)), _box_object(2, (0.04, 0.0, 0.04))]  # 1 cm into each other
    touching = [_box_object(3, (0.0, 0.2, 0.04)), _box_object(4, (0.0499, 0.2, 0.04))]  # 0.1 mm apart
    twin = Twin(overlapping + touching, 0.0, 0.01)
    names = {i: twin.body_name(i) for i in (1, 2, 3, 4)}
    assert twin.overlapping == [(0, 1)]
    data = mujoco.MjData(twin.model)
    state = twin.initial_state(robot.HOME_Q, robot.GRIPPER_OPEN_M)
    mujoco.mj_setState(twin.model, data, state, STATE_SPEC)
    twin.model.opt.enableflags &= ~int(mujoco.mjtEnableBit.mjENBL_SLEEP)
    mujoco.mj_forward(twin.model, data)
    assert _contacts_between(twin.model, data, names[1], names[2]) == 0
    # the touching pair still pushes: box 3 driven into box 4 moves it
    start = data.xpos[twin.model.body(names[4]).id].copy()
    qvel = twin.model.body(names[3]).dofadr[0]
    for _ in range(20):
        data.qvel[qvel] = 0.3
        mujoco.mj_step(twin.model, data)
    assert data.xpos[twin.model.body(names[4]).id][0] - start[0] > 0.01
    assert Twin(overlapping, 0.0, 0.01, overlap_exclude_m=0.02).overlapping == []


def test_twin_uses_the_friction_it_is_given():
    twin = Twin([_box_object(3, (0.0, 0.0, 0.04))], 0.0, 0.01, friction=0.4)
    table = twin.model.geom("table").id
    part = twin.model.body_geomadr[twin.model.body(twin.body_name(3)).id]
    assert twin.model.geom_friction[table, 0] == pytest.approx(0.4)
    assert twin.model.geom_friction[part, 0] == pytest.approx(0.4)
    with pytest.raises(TwinError, match="friction"):
        Twin([], 0.0, friction=-1.0)


def test_the_robot_stands_where_the_base_parameter_puts_it_on_the_table():
    twin = Twin([_box_object(1, (0.0, 0.0, 0.04))], 0.12, 0.01, robot_base_xy=(-0.4, 0.2))
    data = mujoco.MjData(twin.model)
    mujoco.mj_forward(twin.model, data)
    assert np.allclose(data.xpos[twin.model.body("panda_link0").id], [-0.4, 0.2, 0.12])
    default = Twin([_box_object(1, (0.0, 0.0, 0.04))], 0.0, 0.01)
    data = mujoco.MjData(default.model)
    mujoco.mj_forward(default.model, data)
    assert np.allclose(data.xpos[default.model.body("panda_link0").id], [-0.55, 0.0, 0.0])
