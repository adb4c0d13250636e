"""The realistic visual domain: same geometry as the plain one, textured, furnished, with sensor artefacts."""

import numpy as np
import pytest
import trimesh

from arm_core.camera import look_at
from arm_sim.appearance import SceneAppearance, apply_camera_response, sample_appearance, sample_camera_response
from arm_sim.depth_noise import DepthNoise, SensorArtefacts, apply_sensor_artefacts
from arm_sim.objects import ObjectModel, object_pool
from arm_sim.scenes import PlacedObject, Scene, cluttered_scene
from arm_sim.textures import cube_texture, object_panorama
from arm_sim.world import FLOOR_DROP_M, SimWorld

CAMERA = look_at((0.9, 0.3, 0.6), (0.0, 0.0, 0.0))


def _box_scene(appearance_seed: int | None, dark: bool = False, shiny: bool = False) -> Scene:
    box = trimesh.creation.box((0.08, 0.08, 0.12))
    box.apply_translation((0, 0, 0.06))
    T = np.eye(4)
    scene = Scene([PlacedObject(ObjectModel("box", "box", box, [box]), 1.0, T, (0.8, 0.2, 0.2, 1.0))])
    if appearance_seed is None:
        return scene
    rng = np.random.default_rng(appearance_seed)
    appearance = sample_appearance(rng, 1, 0.0, scene.table_half_extent_m, -FLOOR_DROP_M)
    appearance.objects[0].dark, appearance.objects[0].shiny = dark, shiny
    return Scene(scene.objects, appearance=appearance)


def test_realistic_domain_keeps_the_plain_geometry():
    pool = object_pool(split="heldout")
    plain = cluttered_scene(pool, np.random.default_rng(3), n_objects=5, domain="plain")
    realistic = cluttered_scene(pool, np.random.default_rng(3), n_objects=5, domain="realistic")
    assert plain.appearance is None and isinstance(realistic.appearance, SceneAppearance)
    assert len(realistic.appearance.objects) == len(realistic.objects) == len(plain.objects)
    for a, b in zip(plain.objects, realistic.objects, strict=True):
        assert a.model.name == b.model.name and np.allclose(a.T_world_object, b.T_world_object)
    with pytest.raises(ValueError, match="visual domain"):
        plain.with_domain("cartoon", np.random.default_rng(0))


def test_surroundings_are_background_and_objects_are_textured():
    world = SimWorld(_box_scene(appearance_seed=1), robot_arm=False)
    frame = world.render(CAMERA, noise=DepthNoise(enabled=False), rng=np.random.default_rng(0))
    world.close()
    names = {world.model.geom(i).name for i in range(world.model.ngeom)}
    assert {"table_leg_0", "wall_0"} <= names
    assert set(np.unique(frame.labels)) == {0, 1}  # legs, walls, furniture: never objects
    assert world.model.ntex >= 4 and world.model.geom("object_0_part_0").matid >= 0


def test_render_is_deterministic_for_a_seed():
    scene = _box_scene(appearance_seed=2)
    frames = []
    for _ in range(2):
        world = SimWorld(scene, robot_arm=False)
        frames.append(world.render(CAMERA, rng=np.random.default_rng(5)))
        world.close()
    assert np.array_equal(frames[0].rgb, frames[1].rgb) and np.array_equal(frames[0].depth_m, frames[1].depth_m)


def test_dark_surfaces_lose_depth_and_plain_ones_keep_it():
    def lost_on_object(dark: bool) -> float:
        world = SimWorld(_box_scene(appearance_seed=4, dark=dark), robot_arm=False)
        frame = world.render(CAMERA, rng=np.random.default_rng(0))
        world.close()
        on = frame.labels == 1
        return float(np.mean(frame.depth_m[on] == 0))

    assert lost_on_object(dark=True) > 0.3
    assert lost_on_object(dark=False) < 0.1


def test_sensor_artefacts_flying_pixels_and_misregistration():
    depth = np.full((40, 40), 1.0, np.float32)
    depth[10:30, 10:30] = 0.5  # a box in front of a wall
    rgb = np.zeros((40, 40, 3), np.uint8)
    none = np.zeros((40, 40), bool)
    rng = np.random.default_rng(0)
    out = apply_sensor_artefacts(depth, rgb, none, none, (0, 0), rng, SensorArtefacts(flying_fraction=1.0))
    between = (out > 0.55) & (out < 0.95)
    assert between[10:30, 10:30].sum() > 20 and not between[:8].any()  # only at the box's border
    shifted = apply_sensor_artefacts(depth, rgb, none, none, (1, 0), rng, SensorArtefacts(flying_fraction=0.0))
    assert np.array_equal(shifted[:, 11:31], depth[:, 10:30]) and np.all(shifted[:, 0] == 0)
    shiny = np.ones((40, 40), bool)
    rgb[:20] = 255  # a highlight
    lost = apply_sensor_artefacts(depth, rgb, none, shiny, (0, 0), rng, SensorArtefacts(shiny_dropout=0.0))
    assert np.all(lost[:20] == 0) and np.all(lost[21:] > 0)


def test_camera_response_changes_colour_not_shape():
    rgb = np.full((30, 40, 3), 128, np.uint8)
    out = apply_camera_response(rgb, sample_camera_response(np.random.default_rng(0)), np.random.default_rng(1))
    assert out.shape == rgb.shape and out.dtype == np.uint8 and out.std() > 0


def test_object_designs_have_several_colours():
    rng = np.random.default_rng(0)
    for pattern in ("bands", "label", "stripes", "print"):
        panorama = object_panorama(rng, 32, pattern, dark=False)
        assert len(np.unique((panorama * 8).astype(int).reshape(-1, 3), axis=0)) > 4
        assert cube_texture(panorama, np.ones(3)).shape == (6 * 32, 32, 3)
    dark = object_panorama(rng, 32, "plain", dark=True)
    assert dark.mean() < 0.1


def test_every_design_fits_its_panorama():
    rng = np.random.default_rng(0)
    for _ in range(300):  # labels near the bottom once overran the image
        for pattern in ("label", "print", "bands"):
            assert object_panorama(rng, 48, pattern, dark=bool(rng.uniform() < 0.5)).shape == (48, 192, 3)
