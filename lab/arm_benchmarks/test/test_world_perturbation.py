"""Perturbed worlds for robust success: draws within their ranges, and a world without perturbation
is the nominal one."""

import numpy as np

from arm_benchmarks.world_perturbation import PerturbedDraw, WorldPerturbation, draw, moved_poses, perturbed_world
from arm_sim import robot
from arm_sim.objects import object_pool
from arm_sim.scenes import cluttered_scene
from arm_sim.world import SimWorld


def _scene():
    return cluttered_scene(object_pool(split="train", seed=0), np.random.default_rng(3), n_objects=3, domain="plain")


def test_draws_stay_within_their_ranges():
    spec = WorldPerturbation()
    for seed in range(20):
        d = draw(spec, 4, np.random.default_rng(seed))
        assert np.all(np.abs(d.shifts_m) <= spec.shift_m) and np.all(np.abs(d.turns_rad) <= np.deg2rad(spec.turn_deg))
        assert np.all((0.5 <= d.friction_scales) & (d.friction_scales <= 1.5))
        assert np.all((0.7 <= d.mass_scales) & (d.mass_scales <= 1.3)) and 0.0 <= d.latency_s <= 0.04
        assert np.all(np.abs(d.joint_offsets_rad) <= np.deg2rad(spec.joint_offset_deg))


def test_a_pose_is_turned_about_the_vertical_through_its_origin_and_shifted():
    T = np.eye(4)
    T[:3, 3] = (0.1, 0.2, 0.05)
    (moved,) = moved_poses([T], np.array([[0.003, -0.002]]), np.array([np.pi / 2]))
    assert np.allclose(moved[:3, 3], (0.103, 0.198, 0.05)) and np.allclose(moved[:3, 0], (0.0, 1.0, 0.0))


def test_the_draw_changes_friction_mass_and_joints_and_no_draw_leaves_the_world_as_it_was():
    scene = _scene()
    n = len(scene.objects)
    nominal = SimWorld(scene, robot_arm=True)
    null = PerturbedDraw(np.zeros((n, 2)), np.zeros(n), np.ones(n), np.ones(n), 0.0, np.zeros(7))
    same = perturbed_world(scene, null)
    nominal.settle(0.3)
    for a, b in zip(nominal.object_poses(), same.object_poses(), strict=True):
        assert np.allclose(a, b, atol=1e-9)
    d = draw(WorldPerturbation(), n, np.random.default_rng(1))
    changed = perturbed_world(scene, d)
    body = changed.object_ids[0]
    assert np.isclose(changed.model.body_mass[body], nominal.model.body_mass[body] * d.mass_scales[0])
    geom = np.flatnonzero(changed.model.geom_bodyid == body)[0]
    assert np.isclose(changed.model.geom_friction[geom, 0], nominal.model.geom_friction[geom, 0] * d.friction_scales[0])
    assert np.allclose(changed.joint_positions()[:7], robot.HOME_Q + d.joint_offsets_rad, atol=2e-3)
    for world in (nominal, same, changed):
        world.close()
