"""arm_segmentation speed figures for bench_perf: segmentation latency per 640x480 frame."""

import os
import time

import numpy as np
from tqdm import tqdm

from arm_benchmarks.stats import median
from arm_segmentation.baseline import segment_baseline
from arm_segmentation.segmentation import segment
from arm_sim.objects import object_pool
from arm_sim.views import render_benchmark_view


def _frames(n_frames: int, seed: int):
    pool = object_pool(split="heldout", seed=seed)
    frames = []
    for k in tqdm(range(n_frames), desc="render", leave=False):
        rng = np.random.default_rng([seed, k])
        frames.append(render_benchmark_view(pool, rng, (3, 20), with_visibility=False)[1])
    return frames


def _median_ms(fn, frames, repeats: int) -> tuple[float, float]:
    """(median wall ms, median process CPU ms) per call."""
    wall, cpu = [], []
    for frame in tqdm(frames, desc=fn.__name__, leave=False):
        for _ in range(repeats):
            start, start_cpu = time.perf_counter(), time.process_time()
            fn(frame.rgb, frame.depth_m, frame.K, frame.T_world_camera)
            wall.append(time.perf_counter() - start)
            cpu.append(time.process_time() - start_cpu)
    return 1e3 * median(wall), 1e3 * median(cpu)


def measure(n_frames: int = 6, repeats: int = 3, seed: int = 123) -> dict:
    """Median wall and CPU time (ms) per 640x480 frame of the default segmentation and the baseline.

    The wall time includes waiting for a core when the machine is shared; the process CPU time
    (all threads) is what one frame costs.
    """
    frames = _frames(n_frames, seed)
    segment(frames[0].rgb, frames[0].depth_m, frames[0].K, frames[0].T_world_camera)  # warm-up
    wall_ms, cpu_ms = _median_ms(segment, frames, repeats)
    baseline_wall_ms, baseline_cpu_ms = _median_ms(segment_baseline, frames, 1)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return {
        "segmentation_ms": wall_ms,
        "segmentation_cpu_ms": cpu_ms,
        "segmentation_baseline_ms": baseline_wall_ms,
        "segmentation_baseline_cpu_ms": baseline_cpu_ms,
        "segmentation_frame": f"{frames[0].rgb.shape[1]}x{frames[0].rgb.shape[0]}",
        "segmentation_load_average": load,
    }
