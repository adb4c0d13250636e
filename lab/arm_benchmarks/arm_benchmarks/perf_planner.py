"""arm_planner speed figures for results/perf/summary.json (collected by bench_perf).

- mppi_step_ms: median wall time of one MPPI step (25 paths x horizon 5 at 0.02 s, reward included)
  while planning a grasp in a twin holding 10 objects with reconstruction-style convex parts
  (arm_reconstruction's decomposer, <= 8 parts each), at the default twin step.
- mppi_rollout_scaling: rollouts/s and physics steps/s of the batched rollouts for paths x horizon x
  threads, from a state with the hand among the objects.
- twin_timestep_fidelity: for each twin physics step, the MPPI step cost and how far the target's
  final position in the twin lands from the ground-truth world (0.002 s step, true meshes) when the
  same planned controls are replayed open loop; the basis for the default twin step.
"""

from __future__ import annotations

import os
import time

import mujoco
import numpy as np
from tqdm import tqdm

from arm_benchmarks.bench_manip import GOALS, ground_truth_objects
from arm_benchmarks.stats import median, percentile
from arm_planner.mppi import STATE_SPEC, BatchedRollout, MppiConfig, free_body_trees, set_sleep
from arm_planner.planner import PlannerConfig
from arm_planner.session import ManipulationSession
from arm_planner.twin import Twin, TwinObject, decompose
from arm_sim import robot
from arm_sim.objects import object_pool
from arm_sim.scenes import cluttered_scene
from arm_sim.world import SimWorld

TWIN_STEPS_S = (0.002, 0.004, 0.01, 0.02)


def _scene(n_objects: int, seed: int):
    rng = np.random.default_rng(seed)
    return cluttered_scene(object_pool(split="heldout"), rng, n_objects=n_objects)


def _reconstruction_style_objects(scene) -> list[TwinObject]:
    objects = []
    for i, placed in enumerate(scene.objects):
        model = placed.model.scaled(placed.scale)
        objects.append(TwinObject(i + 1, placed.T_world_object, model.mesh, decompose(model.mesh), 1.0, "perf"))
    return objects


def _central_object(scene) -> int:
    xy = np.array([o.T_world_object[:2, 3] for o in scene.objects])
    return int(np.argmin(np.linalg.norm(xy - np.array([0.0, 0.0]), axis=1))) + 1


def _plan(objects, table_height_m, target_id, task, displacement, twin_step_s, steps, nthread=2):
    config = PlannerConfig(mppi=MppiConfig(steps=steps, nthread=nthread), realtime_factor=0.0)
    session = ManipulationSession(config, twin_step_s)
    session.set_objects(objects, table_height_m)
    outcome = session.request(task, target_id, displacement, 0.0, robot.HOME_Q, robot.GRIPPER_OPEN_M)
    return session, outcome


def mppi_step_ms(objects, table_height_m, target_id, twin_step_s=0.01, steps=60) -> tuple[float, object]:
    """Median wall ms of one MPPI step over a grasp plan (first 5 steps skipped as warm-up)."""
    session, outcome = _plan(objects, table_height_m, target_id, "grasp", (0, 0, 0), twin_step_s, steps)
    if not outcome.planned:
        raise RuntimeError(f"perf plan failed: {outcome.message}")
    return median(outcome.result.step_ms[5:]), (session, outcome)


def rollout_scaling(session, outcome, paths=(25, 50, 100), horizons=(5, 10), threads=(1, 2), repeats=5) -> list:
    """Rollouts/s from the state reached after the plan's first half (hand among the objects)."""
    twin, planner = session.twin, session.planner
    model = twin.model
    data = mujoco.MjData(model)
    set_sleep(model, free_body_trees(model), start_asleep=True)
    mujoco.mj_setState(model, data, twin.initial_state(robot.HOME_Q, robot.GRIPPER_OPEN_M), STATE_SPEC)
    controls = outcome.result.controls
    half = controls[: len(controls) // 2]
    rollout = BatchedRollout(model, 0.02, 0)
    state = rollout(np.asarray(_state(model, data)), half[None], data.ctrl.copy())[0, -1]
    rollout.close()
    rng = np.random.default_rng(0)
    rows = []
    for n_threads in threads:
        batched = BatchedRollout(model, 0.02, n_threads)
        for n in paths:
            for h in horizons:
                seqs = half[-1] + rng.normal(scale=0.02, size=(n, h, model.nu))
                batched(state, seqs, half[-1])
                start = time.perf_counter()
                for _ in range(repeats):
                    batched(state, seqs, half[-1])
                seconds = (time.perf_counter() - start) / repeats
                rows.append(
                    {
                        "paths": n,
                        "horizon": h,
                        "threads": n_threads,
                        "ms": 1e3 * seconds,
                        "rollouts_per_s": n / seconds,
                        "physics_steps_per_s": n * h * batched.substeps / seconds,
                    }
                )
        batched.close()
    del planner
    return rows


def _state(model, data) -> np.ndarray:
    state = np.empty(mujoco.mj_stateSize(model, STATE_SPEC))
    mujoco.mj_getState(model, data, state, STATE_SPEC)
    return state


def _replay_twin(objects, table_height_m, target_id, twin_step_s, controls) -> np.ndarray:
    """Target centre displacement after replaying controls open loop in a twin with this step."""
    twin = Twin(objects, table_height_m, twin_step_s)
    model = twin.model
    data = mujoco.MjData(model)
    mujoco.mj_setState(model, data, twin.initial_state(robot.HOME_Q, robot.GRIPPER_OPEN_M), STATE_SPEC)
    mujoco.mj_forward(model, data)
    body = model.body(twin.body_name(target_id)).id
    start = data.xipos[body].copy()
    rollout = BatchedRollout(model, 0.02, 0)
    final = rollout(_state(model, data), controls[None], data.ctrl.copy())[0, -1]
    rollout.close()
    mujoco.mj_setState(model, data, final, STATE_SPEC)
    mujoco.mj_forward(model, data)
    return data.xipos[body] - start


def _replay_world(scene, target_index, result) -> np.ndarray:
    world = SimWorld(scene, robot_arm=True)
    body = world.object_ids[target_index]
    start = world.data.xipos[body].copy()
    world.execute(result.times_s, result.joint_positions)
    end = world.data.xipos[body].copy()
    world.close()
    return end - start


def timestep_fidelity(scene, seeds=(0, 1), steps=200) -> list:
    """Per twin step: MPPI step ms and |twin - world| of the target's final displacement over plans."""
    objects = ground_truth_objects(scene)
    target = _central_object(scene)
    plans = []
    for task in ("grasp", "push"):
        session, outcome = _plan(objects, scene.table_height_m, target, task, GOALS[task], 0.01, steps)
        session.close()
        if outcome.planned:
            plans.append((task, outcome.result, _replay_world(scene, target - 1, outcome.result)))
    rows = []
    for step_s in tqdm(TWIN_STEPS_S, desc="twin step fidelity", leave=False):
        errors = [
            float(np.linalg.norm(_replay_twin(objects, scene.table_height_m, target, step_s, r.controls) - world))
            for _, r, world in plans
        ]
        cost, (session, _) = mppi_step_ms(objects, scene.table_height_m, target, step_s, steps=30)
        session.close()
        rows.append(
            {
                "twin_timestep_s": step_s,
                "mppi_step_ms": cost,
                "replay_error_m": dict(zip([t for t, _, _ in plans], errors, strict=True)),
            }
        )
    return rows


def measure(n_objects: int = 10, seed: int = 0) -> dict:
    scene = _scene(n_objects, seed)
    objects = _reconstruction_style_objects(scene)
    target = _central_object(scene)
    step_ms, (session, outcome) = mppi_step_ms(objects, scene.table_height_m, target)
    scaling = rollout_scaling(session, outcome)
    session.close()
    load_before = os.getloadavg()[0]
    figures = {
        "mppi_step_ms": step_ms,
        "mppi_step_p90_ms": percentile(outcome.result.step_ms[5:], 90),
        "mppi_step_cpu_ms": median(outcome.result.step_cpu_ms[5:]),
        "mppi_load_average": load_before,
        "mppi_step_config": "25 paths x horizon 5 x 0.02 s, twin step 0.01 s, 2 threads, "
        f"{len(objects)} objects with <= 8 convex parts, grasp reward",
        "mppi_rollout_scaling": scaling,
        "mppi_cpu_count": os.cpu_count(),
    }
    if os.environ.get("ARM_PERF_FIDELITY", "1") != "0":
        figures["twin_timestep_fidelity"] = timestep_fidelity(scene)
    return figures
