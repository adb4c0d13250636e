import mujoco
import numpy as np
import pytest
import trimesh

from arm_core.camera import look_at
from arm_sim import robot
from arm_sim.depth_noise import DepthNoise
from arm_sim.objects import ObjectModel, make_object, object_pool
from arm_sim.scenes import (
    TASK_TARGET_XY,
    PlacedObject,
    Scene,
    _slide_into_range,
    _visible_fraction,
    cluttered_scene,
    task_camera_pose,
    task_scene,
)
from arm_sim.world import ROBOT_BASE_XY, SimWorld, build_world


def _base():
    T = np.eye(4)
    T[:2, 3] = ROBOT_BASE_XY
    return T


def test_robot_kinematics_match_the_dh_parameters():
    world = SimWorld(Scene(), robot_arm=True)
    site = world.model.site(robot.TCP_SITE).id
    for q in np.random.default_rng(0).uniform(robot.JOINT_LIMITS[:, 0], robot.JOINT_LIMITS[:, 1], (5, 7)):
        world.set_robot_state(q, 0.02)
        assert np.allclose(robot.forward_kinematics(q, _base())[:3, 3], world.data.site_xpos[site], atol=1e-6)


def test_position_servos_track_a_trajectory():
    world = SimWorld(Scene(), robot_arm=True)
    goal = np.concatenate([robot.HOME_Q + np.array([0.3, 0.2, -0.2, 0.3, 0.2, -0.2, 0.3]), [0.01]])
    world.execute(np.array([1.0, 2.0]), np.stack([goal, goal]))
    assert np.max(np.abs(world.joint_positions() - goal)) < 0.01


def test_builder_makes_one_free_body_per_object_with_its_parts():
    model = make_object("mug", np.random.default_rng(0))
    T = np.eye(4)
    T[:3, 3] = (0.1, 0.0, 0.0)
    scene = Scene([PlacedObject(model, 1.0, T)])
    mj = build_world(scene, robot_arm=False)
    body = mj.body("object_0")
    assert mj.body_jntnum[body.id] == 1 and mj.nmesh == len(model.convex_parts)
    data = mujoco.MjData(mj)
    mujoco.mj_forward(mj, data)
    assert np.allclose(data.xpos[body.id], (0.1, 0.0, 0.0))


def test_cluttered_scene_settles_on_the_table_and_renders_labels():
    rng = np.random.default_rng(5)
    scene = cluttered_scene(object_pool(split="train"), rng, n_objects=6)
    assert 3 <= len(scene.objects) <= 6
    world = SimWorld(scene, robot_arm=False)
    before = [T[:3, 3].copy() for T in world.object_poses()]
    world.settle(1.0)
    moved = [np.linalg.norm(T[:3, 3] - b) for T, b in zip(world.object_poses(), before, strict=True)]
    assert np.median(moved) < 0.01  # the generator hands back settled poses
    frame = world.render(look_at((0.6, 0.3, 0.6), (0.0, 0.0, 0.0)), rng=rng)
    assert frame.rgb.shape == (480, 640, 3) and frame.depth_m.dtype == np.float32
    visible = set(np.unique(frame.labels)) - {0}
    assert visible and visible <= set(range(1, len(scene.objects) + 1))
    assert np.all((frame.visible_fraction >= 0) & (frame.visible_fraction <= 1))
    assert frame.depth_m[frame.labels > 0].mean() > 0.2


def test_task_scene_reaches_the_requested_visibility():
    rng = np.random.default_rng(2)
    target = make_object("can", rng)
    scene, index, camera = task_scene(target, object_pool(split="heldout"), rng, visible_range=(0.3, 0.7))
    world = SimWorld(scene, robot_arm=False)
    fraction = world.render(camera, noise=DepthNoise(enabled=False)).visible_fraction[index]
    assert 0.2 <= fraction < 0.8  # settling may shift it slightly


def test_an_occluder_that_hides_too_much_is_slid_sideways_into_the_visibility_bin():
    rng = np.random.default_rng(0)
    camera = task_camera_pose()
    target, wall = make_object("box", rng), make_object("box", rng)
    scale = 0.3 / float(np.max(wall.mesh.extents))  # a 30 cm box straight in front of the target

    def placed(model, s, xy):
        T = np.eye(4)
        T[:2, 3] = xy
        T[2, 3] = -float(model.mesh.bounds[0, 2]) * s
        return PlacedObject(model, s, T)

    scene = Scene([placed(target, 1.0, TASK_TARGET_XY)])
    occluder_xy = (TASK_TARGET_XY[0] + 0.2, TASK_TARGET_XY[1] + 0.01)
    occluder = placed(wall, scale, occluder_xy)
    assert _visible_fraction(Scene([*scene.objects, occluder]), 0, camera) < 0.1
    target_disc = (TASK_TARGET_XY, 0.5 * float(np.max(target.mesh.extents[:2])))
    disc = (occluder_xy, 0.5 * float(np.max(wall.mesh.extents[:2])) * scale)
    slid, fraction, new_disc = _slide_into_range(scene, occluder, disc, [target_disc], (0.4, 0.6), camera)
    assert slid is not None and 0.4 <= fraction < 0.6
    assert new_disc[0][1] > occluder_xy[1] and slid.objects[1].T_world_object[1, 3] == new_disc[0][1]
    assert abs(_visible_fraction(slid, 0, camera) - fraction) < 1e-9


def test_scene_friction_decides_whether_a_pushed_box_slides():
    box = trimesh.creation.box((0.06, 0.06, 0.04))
    model = ObjectModel("box", "box", box, [box.copy()])
    T = np.eye(4)
    T[2, 3] = 0.02
    moved = {}
    for friction in (0.5, 0.9):
        mj = build_world(Scene([PlacedObject(model, 1.0, T)], friction=friction), robot_arm=False)
        data = mujoco.MjData(mj)
        body = mj.body("object_0").id
        weight = float(mj.body_subtreemass[body]) * 9.81
        for _ in range(int(0.5 / mj.opt.timestep)):
            data.xfrc_applied[body, 0] = 0.7 * weight  # pushed at its centre of mass: it cannot tip
            mujoco.mj_step(mj, data)
        moved[friction] = float(data.xpos[body, 0])
    assert moved[0.5] > 0.05 and abs(moved[0.9]) < 0.005
    with pytest.raises(ValueError, match="friction"):
        build_world(Scene(friction=0.0), robot_arm=False)


def test_objects_overlapping_as_built_get_no_contact_and_stay_put():
    """Two boxes whose parts overlap by 4 cm as built (reconstructed neighbours' convex parts do):
    without the exclusion MuJoCo pushes them 2 cm apart within 1 s; with it (in the spec, so in its
    MJCF too) they rest where they were built. A box 3 cm off the others keeps its contacts."""
    from arm_sim.scenes import PlacedObject, Scene
    from arm_sim.world import compile_without_overlap_contacts, world_spec

    box = trimesh.creation.box(extents=(0.06, 0.06, 0.06))
    poses = []
    for x in (0.0, 0.02, 0.11):  # the first two overlap by 4 cm, the third stands 3 cm off
        T = np.eye(4)
        T[:3, 3] = (x, 0.0, 0.03)
        poses.append(T)
    scene = Scene([PlacedObject(ObjectModel(f"b{i}", "box", box, [box]), 1.0, T) for i, T in enumerate(poses)])
    spec = world_spec(scene, robot_arm=False)
    model, pairs = compile_without_overlap_contacts(spec, 3)
    assert pairs == [(0, 1)] and "exclude" in spec.to_xml()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    start = data.xpos.copy()
    mujoco.mj_step(model, data, nstep=500)
    assert np.abs(data.xpos - start).max() < 0.005
    pushed = build_world(scene, robot_arm=False)
    data = mujoco.MjData(pushed)
    mujoco.mj_step(pushed, data, nstep=500)
    assert np.abs(data.xpos - start).max() > 0.015, "without the exclusion they are pushed apart"
