"""arm_segmentation speed figures for bench_perf: segmentation latency per 640x480 frame."""

import time

import numpy as np
from tqdm import tqdm

from arm_segmentation.baseline import segment_baseline
from arm_segmentation.segmentation import segment


def _frames(n_frames: int, seed: int):
    from arm_sim.camera import sample_camera_pose
    from arm_sim.objects import object_pool
    from arm_sim.scenes import cluttered_scene
    from arm_sim.world import SimWorld

    pool = object_pool(split="heldout", seed=seed)
    frames = []
    for k in tqdm(range(n_frames), desc="render", leave=False):
        rng = np.random.default_rng([seed, k])
        scene = cluttered_scene(pool, rng, n_objects=int(rng.integers(3, 21)))
        world = SimWorld(scene, robot_arm=False)
        frames.append(world.render(sample_camera_pose(rng, scene.table_centre), rng=rng, with_visibility=False))
        world.close()
    return frames


def _median_ms(fn, frames, repeats: int) -> float:
    times = []
    for frame in tqdm(frames, desc=fn.__name__, leave=False):
        for _ in range(repeats):
            start = time.perf_counter()
            fn(frame.rgb, frame.depth_m, frame.K, frame.T_world_camera)
            times.append(time.perf_counter() - start)
    return 1e3 * float(np.median(times))


def measure(n_frames: int = 6, repeats: int = 3, seed: int = 123) -> dict:
    """Median wall time (ms) of the default segmentation and of the baseline on simulated frames."""
    frames = _frames(n_frames, seed)
    segment(frames[0].rgb, frames[0].depth_m, frames[0].K, frames[0].T_world_camera)  # warm-up
    cpu_start = time.process_time()
    wall_start = time.perf_counter()
    segmentation_ms = _median_ms(segment, frames, repeats)
    cpu_share = (time.process_time() - cpu_start) / max(time.perf_counter() - wall_start, 1e-9)
    return {
        "segmentation_ms": segmentation_ms,
        "segmentation_cpu_per_wall": cpu_share,
        "segmentation_baseline_ms": _median_ms(segment_baseline, frames, 1),
        "segmentation_frame": f"{frames[0].rgb.shape[1]}x{frames[0].rgb.shape[0]}",
    }
