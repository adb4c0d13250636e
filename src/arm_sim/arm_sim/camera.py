"""Simulated camera: the optical-to-MuJoCo camera axes and the benchmark's camera-pose sampling.

MuJoCo cameras look along their -z with +y up, i.e. R_world_mjcam = R_world_camera @ diag(1, -1, -1).
"""

import numpy as np

from arm_core.camera import look_at

OPTICAL_TO_MUJOCO = np.diag([1.0, -1.0, -1.0])


def sample_camera_pose(
    rng: np.random.Generator,
    table_centre,
    min_distance_m: float = 0.125,
    max_distance_m: float = 1.5,
    min_elevation_deg: float = 15.0,
) -> np.ndarray:
    """A camera pose as in the paper's benchmark table: position uniform in the half-shell between
    min and max distance above the table centre, looking at a random point in a sphere of radius
    min(distance / 2, 0.25). A minimum elevation keeps the table in view."""
    table_centre = np.asarray(table_centre, dtype=np.float64)
    while True:
        direction = rng.normal(size=3)
        direction[2] = abs(direction[2])
        direction /= np.linalg.norm(direction)
        if np.degrees(np.arcsin(direction[2])) >= min_elevation_deg:
            break
    radius = rng.uniform(min_distance_m**3, max_distance_m**3) ** (1.0 / 3.0)
    eye = table_centre + radius * direction
    offset = rng.normal(size=3)
    offset *= min(radius / 2, 0.25) * rng.uniform() ** (1 / 3) / np.linalg.norm(offset)
    return look_at(eye, table_centre + offset)
