"""arm_sim speed figures: 640x480 RGB-D rendering (with labels, noise and visible fractions) of
10-object scenes with the robot, per visual domain. The realistic domain casts shadows in about half
of its scenes (a second render pass), so it is measured over several scenes."""

import time

import numpy as np
from tqdm import tqdm

from arm_benchmarks.stats import mean
from arm_sim.appearance import DOMAINS
from arm_sim.objects import object_pool
from arm_sim.scenes import cluttered_scene, task_camera_pose
from arm_sim.world import SimWorld


def _scene_render_s(seed: int, domain: str, frames: int, n_objects: int) -> tuple[float, float, bool]:
    """(seconds per RGB-D + labels frame, seconds with visible fractions, shadows on) for one scene."""
    rng = np.random.default_rng(seed)
    scene = cluttered_scene(object_pool(split="heldout"), rng, n_objects=n_objects, domain=domain)
    world = SimWorld(scene, robot_arm=True)
    camera = task_camera_pose()
    world.render(camera, rng=rng)  # warm-up: context creation
    start = time.perf_counter()
    for _ in tqdm(range(frames), desc=f"render {domain} scene {seed}", leave=False):
        world.render(camera, rng=rng, with_visibility=False)
    rgbd_s = (time.perf_counter() - start) / frames
    start = time.perf_counter()
    for _ in range(3):
        world.render(camera, rng=rng, with_visibility=True)
    full_s = (time.perf_counter() - start) / 3
    world.close()
    return rgbd_s, full_s, bool(scene.appearance is not None and scene.appearance.shadows)


def measure(frames: int = 20, n_objects: int = 10, seed: int = 0, scenes: int = 4) -> dict:
    figures = {}
    for domain in DOMAINS:
        count = scenes if domain == "realistic" else 1
        runs = [_scene_render_s(seed + k, domain, frames, n_objects) for k in range(count)]
        rgbd_s = mean([r[0] for r in runs])
        prefix = "render" if domain == "plain" else "render_realistic"
        figures |= {
            f"{prefix}_fps": 1.0 / rgbd_s,
            f"{prefix}_fps_slowest_scene": 1.0 / max(r[0] for r in runs),
            f"{prefix}_ms": 1e3 * rgbd_s,
            f"{prefix}_with_visibility_ms": 1e3 * mean([r[1] for r in runs]),
        }
        if domain == "realistic":
            figures[f"{prefix}_scenes_with_shadows"] = f"{sum(r[2] for r in runs)} of {len(runs)}"
    return figures
