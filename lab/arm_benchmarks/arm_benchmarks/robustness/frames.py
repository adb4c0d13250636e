"""Input frames rendered by the simulator: seeded, settled cluttered scenes seen by one camera."""

from __future__ import annotations

import numpy as np

from arm_core.camera import look_at
from arm_sim.objects import object_pool
from arm_sim.views import BenchmarkScene

CAMERA_EYE = (0.7, 0.0, 0.5)
CAMERA_TARGET = (0.0, 0.0, 0.05)


def render_frames(
    n_objects: int, width: int = 320, height: int = 240, seed: int = 0, count: int = 1, settle_s: float = 1.0
):
    """`count` noisy renders of one seeded, settled cluttered scene (no robot), as RgbdFrames."""
    rng = np.random.default_rng(seed)
    pool = object_pool(split="heldout", seed=seed) if n_objects else None
    options = dict(scale_range=(0.5, 1.2), drop_std_m=0.08 + 0.004 * n_objects, settle_s=settle_s)
    with BenchmarkScene(pool, rng, n_objects, with_visibility=False, width=width, height=height, **options) as views:
        T_world_camera = look_at(CAMERA_EYE, CAMERA_TARGET)
        return [views.render(T_world_camera) for _ in range(count)]
