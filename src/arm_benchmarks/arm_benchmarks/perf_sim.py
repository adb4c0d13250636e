"""arm_sim speed figures: 640x480 RGB-D rendering (with labels, noise and visible fractions)."""

import time

import numpy as np
from tqdm import tqdm

from arm_sim.objects import object_pool
from arm_sim.scenes import cluttered_scene, task_camera_pose
from arm_sim.world import SimWorld


def measure(frames: int = 20, n_objects: int = 10, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    world = SimWorld(cluttered_scene(object_pool(split="heldout"), rng, n_objects=n_objects), robot_arm=True)
    camera = task_camera_pose()
    world.render(camera, rng=rng)  # warm-up: context creation
    start = time.perf_counter()
    for _ in tqdm(range(frames), desc="render", leave=False):
        world.render(camera, rng=rng, with_visibility=False)
    rgbd_s = (time.perf_counter() - start) / frames
    start = time.perf_counter()
    for _ in range(5):
        world.render(camera, rng=rng, with_visibility=True)
    full_s = (time.perf_counter() - start) / 5
    world.close()
    return {"render_fps": 1.0 / rgbd_s, "render_ms": 1e3 * rgbd_s, "render_with_visibility_ms": 1e3 * full_s}
