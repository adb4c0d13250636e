"""One scene-and-view renderer for the benchmarks and the training data: a seeded cluttered scene,
settled by physics, rendered from the paper's camera distribution or a given pose.

Every random draw comes from the caller's generator, in a fixed order (object count, scene, then per
view the camera pose and the depth noise), so a seed gives the same frames bit for bit.
"""

from __future__ import annotations

import numpy as np

from arm_core.frames import RgbdFrame
from arm_sim.camera import sample_camera_pose
from arm_sim.depth_noise import DepthNoise
from arm_sim.objects import ObjectPool
from arm_sim.scenes import Scene, cluttered_scene
from arm_sim.world import SimWorld


def draw_object_count(rng: np.random.Generator, n_objects: int | tuple[int, int]) -> int:
    """n_objects as is, or drawn uniformly from the inclusive range (low, high)."""
    if isinstance(n_objects, tuple | list):
        low, high = n_objects
        return int(rng.integers(low, high + 1))
    return int(n_objects)


class BenchmarkScene:
    """A settled cluttered scene of `n_objects` from `pool` (0: the bare table, no draw) and its
    renderer (no robot). Use as a context manager; render() as many views as needed.

    scene_options go to arm_sim.scenes.cluttered_scene (scale_range, drop_std_m, settle_s, ...)."""

    def __init__(
        self,
        pool: ObjectPool | None,
        rng: np.random.Generator,
        n_objects: int | tuple[int, int],
        depth_noise: bool = True,
        with_visibility: bool = True,
        width: int = 640,
        height: int = 480,
        **scene_options,
    ):
        self.rng = rng
        self.noise = DepthNoise(enabled=depth_noise)
        self.with_visibility = with_visibility
        n = draw_object_count(rng, n_objects)
        self.scene = cluttered_scene(pool, rng, n_objects=n, **scene_options) if n else Scene()
        self.world = SimWorld(self.scene, robot_arm=False, width=width, height=height)

    def render(self, T_world_camera: np.ndarray | None = None) -> RgbdFrame:
        """One view from T_world_camera, or from a pose of the paper's camera distribution (drawn)."""
        if T_world_camera is None:
            T_world_camera = sample_camera_pose(self.rng, self.scene.table_centre)
        return self.world.render(T_world_camera, self.noise, self.rng, with_visibility=self.with_visibility)

    def close(self) -> None:
        self.world.close()

    def __enter__(self) -> BenchmarkScene:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def render_benchmark_view(
    pool: ObjectPool | None,
    rng: np.random.Generator,
    n_objects: int | tuple[int, int],
    T_world_camera: np.ndarray | None = None,
    **options,
) -> tuple[Scene, RgbdFrame]:
    """(scene, frame): one view of a new benchmark scene; options as BenchmarkScene's."""
    with BenchmarkScene(pool, rng, n_objects, **options) as views:
        return views.scene, views.render(T_world_camera)
