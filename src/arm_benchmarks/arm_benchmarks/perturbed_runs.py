"""Physical outcomes that hold on any CPU: a behaviour is asserted over a few runs whose initial states
differ by far less than a real robot's uncertainty (objects moved by up to 1e-5 m and turned by up to
1e-4 rad, MPPI seeded differently), and must hold in a majority of them. One contact-rich rollout can
flip with the CPU's floating-point rounding; a behaviour that is robust holds across such runs."""

import numpy as np

from arm_sim.scenes import Scene

RUNS, MAJORITY = 3, 2
SHIFT_M, TURN_RAD = 1e-5, 1e-4


def perturbed_scene(scene: Scene, run: int) -> Scene:
    """Run 0: the scene as given; run k > 0: each object moved and turned about z by a draw of seed k."""
    if run == 0:
        return scene
    rng = np.random.default_rng(run)
    poses = []
    for placed in scene.objects:
        angle = rng.uniform(-TURN_RAD, TURN_RAD)
        turn = np.eye(4)
        turn[:2, :2] = [[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]
        T = placed.T_world_object.copy()
        T[:3, :3] = turn[:3, :3] @ T[:3, :3]
        T[:2, 3] += rng.uniform(-SHIFT_M, SHIFT_M, 2)
        poses.append(T)
    return scene.with_poses(poses)


def holds_in_most(attempt, runs: int = RUNS, majority: int = MAJORITY) -> tuple[bool, list]:
    """(whether attempt(k) -> (ok, detail) held in at least `majority` of `runs` runs, the (ok, detail)
    of each run made). Stops as soon as the answer is known."""
    outcomes = []
    for run in range(runs):
        outcomes.append(attempt(run))
        held = sum(ok for ok, _ in outcomes)
        if held >= majority or held + runs - len(outcomes) < majority:
            break
    return sum(ok for ok, _ in outcomes) >= majority, outcomes
