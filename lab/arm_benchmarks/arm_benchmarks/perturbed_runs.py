"""Physical outcomes that hold on any CPU: a behaviour is asserted over a few runs whose initial states
differ by far less than a real robot's uncertainty (objects moved by up to 1e-5 m and turned by up to
1e-4 rad, MPPI seeded differently), and must hold in enough of them (arm_core.repeated_runs). One
contact-rich rollout can flip with the CPU's floating-point rounding; a behaviour that is robust holds
across such runs, and bench_behaviours measures how often each does."""

import numpy as np

from arm_benchmarks.world_perturbation import moved_poses
from arm_sim.scenes import Scene

SHIFT_M, TURN_RAD = 1e-5, 1e-4


def perturbed_scene(scene: Scene, run: int) -> Scene:
    """Run 0: the scene as given; run k > 0: each object moved and turned about z by a draw of seed k."""
    if run == 0:
        return scene
    rng = np.random.default_rng(run)
    draws = [(rng.uniform(-TURN_RAD, TURN_RAD), rng.uniform(-SHIFT_M, SHIFT_M, 2)) for _ in scene.objects]
    turns = np.array([angle for angle, _ in draws])
    shifts = np.array([shift for _, shift in draws]).reshape(-1, 2)
    return scene.with_poses(moved_poses([placed.T_world_object for placed in scene.objects], shifts, turns))
