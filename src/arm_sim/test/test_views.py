import numpy as np
import pytest

from arm_sim.objects import object_pool
from arm_sim.scenes import Scene
from arm_sim.views import BenchmarkScene, draw_object_count, render_benchmark_view


@pytest.fixture(scope="module")
def pool():
    return object_pool(split="heldout", seed=0)


def frame_arrays(frame):
    return [frame.rgb, frame.depth_m, frame.labels, frame.K, frame.T_world_camera, frame.visible_fraction]


def test_same_seed_renders_the_same_frame_bit_for_bit(pool):
    first = render_benchmark_view(pool, np.random.default_rng([4, 1]), (3, 5), width=160, height=120)
    again = render_benchmark_view(pool, np.random.default_rng([4, 1]), (3, 5), width=160, height=120)
    other = render_benchmark_view(pool, np.random.default_rng([4, 2]), (3, 5), width=160, height=120)
    assert 1 <= len(first[0].objects) <= 5
    assert all(np.array_equal(a, b) for a, b in zip(frame_arrays(first[1]), frame_arrays(again[1]), strict=True))
    assert not np.array_equal(first[1].depth_m, other[1].depth_m)
    assert first[1].rgb.shape == (120, 160, 3) and np.all(first[1].visible_fraction >= 0.0)


def test_options_reach_the_renderer_and_the_scene(pool):
    T_world_camera = np.eye(4)
    T_world_camera[:3, 3] = (0.0, 0.0, 1.2)
    T_world_camera[:3, :3] = np.diag([1.0, -1.0, -1.0])  # looking straight down
    with BenchmarkScene(
        pool, np.random.default_rng(0), 2, depth_noise=False, with_visibility=False, width=80, height=60
    ) as views:
        clean = views.render(T_world_camera)
        assert len(views.scene.objects) <= 2 and np.all(clean.visible_fraction == -1.0)
        assert np.array_equal(clean.depth_m, views.render(T_world_camera).depth_m), "no noise: same depth"


def test_no_objects_is_the_bare_table_without_a_draw():
    rng = np.random.default_rng(7)
    with BenchmarkScene(None, rng, 0, width=40, height=30) as views:
        assert views.scene.objects == [] and views.scene.table_rgba == Scene().table_rgba
        assert rng.bit_generator.state == np.random.default_rng(7).bit_generator.state
        assert views.render(np.eye(4)).labels.max() == 0
    assert draw_object_count(np.random.default_rng(0), 4) == 4
    counts = {draw_object_count(np.random.default_rng(s), (3, 5)) for s in range(40)}
    assert counts == {3, 4, 5}
