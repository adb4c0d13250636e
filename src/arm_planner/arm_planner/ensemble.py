"""Twins a little different from the nominal one: MPPI spreads its sampled paths over them, so a
plan is chosen for how it does across the physics a real robot may meet, not in one model.

Each twin scales every object's sliding friction (x0.5-1.5) and mass and inertia (x0.7-1.3), drawn
per object, the ranges bench_manip's robust success executes plans in (arm_benchmarks.world_perturbation).
"""

from __future__ import annotations

import copy

import mujoco
import numpy as np

FRICTION_SCALE = (0.5, 1.5)
MASS_SCALE = (0.7, 1.3)


def scale_object_physics(model: mujoco.MjModel, bodies, friction_scales, mass_scales) -> None:
    """Scale, in place, each object body's geoms' sliding friction and its mass and inertia."""
    for body, friction, mass in zip(bodies, friction_scales, mass_scales, strict=True):
        model.geom_friction[model.geom_bodyid == body, 0] *= friction
        model.body_mass[body] *= mass
        model.body_inertia[body] *= mass


def perturbed_twins(model: mujoco.MjModel, object_bodies: np.ndarray, count: int, seed: int) -> list[mujoco.MjModel]:
    """`count` twins: the nominal model itself first, then copies with the objects' physics scaled by
    draws of a generator seeded with `seed`."""
    rng = np.random.default_rng([seed, 4241])
    twins = [model]
    for _ in range(count - 1):
        twin = copy.copy(model)
        n = len(object_bodies)
        scale_object_physics(twin, object_bodies, rng.uniform(*FRICTION_SCALE, n), rng.uniform(*MASS_SCALE, n))
        twins.append(twin)
    return twins


def follow_nominal(nominal: mujoco.MjModel, twins: list[mujoco.MjModel]) -> None:
    """Copy what the planner changes on the nominal twin while planning (the objects' rest poses and
    sleep policies, the sleep flag) to the other twins."""
    for twin in twins:
        if twin is not nominal:
            twin.qpos0[:] = nominal.qpos0
            twin.tree_sleep_policy[:] = nominal.tree_sleep_policy
            twin.opt.enableflags = nominal.opt.enableflags
