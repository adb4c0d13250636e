"""bench_manip: the paper's cluttered manipulation benchmark (appendix "Cluttered Manipulation Benchmark").

Each episode is one task scene: a target object at a fixed spot, distractors in front of it until its
visible fraction falls in the episode's bin, one RGB-D view from the robot side with ground-truth
instance labels (as in the paper). Every method reconstructs the scene from that view (ground truth
uses the true meshes), the planner plans the task in a twin of that reconstruction, and the plan is
executed in the ground-truth world: closed loop by default (every --observe-period seconds the twin
takes the world's joint states and tracked object poses, or with --tracker depth the poses of its
meshes fitted to a new depth frame; see arm_benchmarks.world_execution), or open loop as in the paper
with --observe-period 0. Success: grasp lifts the target >= 5 cm; push moves it
30 cm right and 5 cm forward, rearrange 20 cm forward and 20 cm left, each ending within 2.5 cm.

Robust success: each method's plan is executed again, as in the nominal world, in --robust-worlds
perturbed copies of the ground-truth world (arm_benchmarks.world_perturbation: objects moved by up to
5 mm and turned by up to 5 degrees, friction x0.5-1.5, masses x0.7-1.3, 0-40 ms of latency, joints off
by up to 0.5 degrees; the same draws for every method of an episode). Closed loop, the planner plans
again from the method's own twin of the view (the perturbation unknown to it) and observes the perturbed
world every --observe-period, its encoders reporting the joints off by the draw's offsets; open loop
(--observe-period 0), the nominal plan's controls are replayed. The robust success is the share of those
executions that meet the task (a goal without a plan fails in all).

Results are appended per (episode, method) to episodes.jsonl, so an interrupted run resumes. Each row
carries the run key (arm_benchmarks.run_key: a digest of the settings, the methods' checkpoints and the source
of the packages that produce the result); rows with another key are moved to episodes.stale.jsonl, never
reused.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import pathlib
import time

import mujoco
import numpy as np
import torch
from tqdm import tqdm

from arm_benchmarks.bench_stats import BINS, bin_label, summarise, write_plots, write_report
from arm_benchmarks.depth_tracking import DepthTracker
from arm_benchmarks.machine import machine_description
from arm_benchmarks.methods import GROUND_TRUTH, GROUND_TRUTH_ALIASES, benchmark_method
from arm_benchmarks.run_key import run_key
from arm_benchmarks.stats import json_safe, median
from arm_benchmarks.world_execution import HOLD_AFTER_S, Reobservation, run_in_world, task_outcome
from arm_benchmarks.world_perturbation import WorldPerturbation, draw, execute_perturbed, perturbed_world
from arm_core.settings import add_arguments, changed, from_arguments, settings_of
from arm_planner.mppi import STATE_SPEC
from arm_planner.planner import PlannerConfig
from arm_planner.session import ManipulationSession
from arm_planner.tasks import TASK_GRASP, TASK_PUSH, TASK_REARRANGE, TASKS
from arm_planner.tasks.grasp import GraspReward
from arm_planner.twin import TwinObject
from arm_reconstruction.checkpoint import default_checkpoint_path
from arm_reconstruction.network import METHODS
from arm_reconstruction.pipeline import reconstruct
from arm_sim import robot
from arm_sim.appearance import DEFAULT_DOMAIN, DOMAINS
from arm_sim.depth_noise import DepthNoise
from arm_sim.objects import object_pool
from arm_sim.scenes import task_scene
from arm_sim.world import SimWorld

GOALS = {
    TASK_GRASP: (0.0, 0.0, 0.0),
    TASK_PUSH: (0.05, -0.30, 0.0),  # 30 cm right (-y), 5 cm forward (+x)
    TASK_REARRANGE: (0.20, 0.20, 0.0),  # 20 cm forward, 20 cm left
}
TOLERANCE_M = 0.025
DEFAULT_METHODS = (GROUND_TRUTH, "baseline", "baseline+E", "arm")


@dataclasses.dataclass(frozen=True)
class Episode:
    index: int
    task: str
    bin_index: int
    seed: int


def plan_episodes(n: int, tasks, bin_indices, seed: int) -> list[Episode]:
    """n episodes cycling over tasks x visibility bins (indices into BINS; each combination before any
    repeats)."""
    combos = [(t, b) for b in bin_indices for t in tasks]
    return [Episode(i, *combos[i % len(combos)], seed * 100_003 + i) for i in range(n)]


def build_scene(
    episode: Episode, bins, target_pool, distractor_pool, target_scale: float, tries: int = 3, domain=DEFAULT_DOMAIN
):
    """(scene, target index, frame) for the episode, or raises RuntimeError when the bin is unreachable."""
    lo, hi = bins[episode.bin_index]
    last = None
    for attempt in range(tries):
        rng = np.random.default_rng([episode.seed, attempt])
        target = target_pool.sample(rng)
        try:
            scene, target_index, camera = task_scene(
                target, distractor_pool, rng, visible_range=(lo, hi), target_scale=target_scale, domain=domain
            )
        except RuntimeError as error:
            last = error
            continue
        world = SimWorld(scene, robot_arm=True)
        frame = world.render(camera, noise=DepthNoise(), rng=rng)
        world.close()
        visible = float(frame.visible_fraction[target_index])
        if lo <= visible < hi:
            return scene, target_index, frame, target.name
        last = RuntimeError(f"visible fraction {visible:.2f} left [{lo}, {hi}) after settling")
    raise RuntimeError(f"no scene for bin {bin_label(bins[episode.bin_index])}: {last}")


def ground_truth_objects(scene) -> list[TwinObject]:
    objects = []
    for i, placed in enumerate(scene.objects):
        model = placed.model.scaled(placed.scale)
        objects.append(TwinObject(i + 1, placed.T_world_object, model.mesh, model.convex_parts, 1.0, GROUND_TRUTH))
    return objects


# Closer to the paper's post-processing (intersections removed, convex parts; Section 3): without the
# stable base, joined parts, depth snapping, solids of revolution and cuboids that every method otherwise gets
# (small parts dropped and floating ones supported from below remain).
PAPER_POSTPROCESSING = {
    "stable_base_tilt_deg": 0.0,
    "join_parts": False,
    "snap_to_depth": False,
    "complete_revolutions": False,
    "complete_cuboids": False,
}


def reconstructed_objects(method: str, frame, settings: dict | None = None) -> list[TwinObject]:
    """The method's reconstruction of the frame's objects; settings: ReconstructionSettings fields."""
    objects = reconstruct(
        frame.rgb, frame.depth_m, frame.K, frame.T_world_camera, frame.labels, method=method, **(settings or {})
    )
    return [
        TwinObject(o.id, o.T_world_object, o.mesh, o.convex_parts, o.visible_fraction, o.method)
        for o in objects
        if o.ok
    ]


def target_stability_m(session: ManipulationSession, target_id: int, objects, table_height_m: float) -> float:
    """How far the target's centre moves in 1 s when its twin (objects as viewed, robot still at home)
    settles: 0 = stable."""
    session.set_objects(objects, table_height_m)
    twin = session.twin
    if twin is None or target_id not in twin:
        return float("nan")
    model = twin.model
    flags = model.opt.enableflags
    model.opt.enableflags = flags & ~int(mujoco.mjtEnableBit.mjENBL_SLEEP)
    data = mujoco.MjData(model)
    poses = {o.id: o.T_world_object for o in objects}
    mujoco.mj_setState(model, data, twin.initial_state(robot.HOME_Q, robot.GRIPPER_OPEN_M, poses), STATE_SPEC)
    mujoco.mj_forward(model, data)
    body = model.body(twin.body_name(target_id)).id
    start = data.xipos[body].copy()
    mujoco.mj_step(model, data, nstep=int(round(1.0 / model.opt.timestep)))
    mujoco.mj_forward(model, data)
    model.opt.enableflags = flags
    return float(np.linalg.norm(data.xipos[body] - start))


def reobservation(tracker: str, objects: list[TwinObject], frame, seed: int) -> Reobservation | None:
    """None for the perfect tracker; for "depth", new frames through the view's camera, the objects'
    poses fitted to them with the method's own meshes (arm_benchmarks.depth_tracking)."""
    if tracker == "perfect":
        return None
    tracker = DepthTracker({o.id: o.mesh for o in objects}, seed=seed)
    return Reobservation(frame.T_world_camera, tracker, DepthNoise(), np.random.default_rng(seed))


def run_task(session, world, objects, scene, target_index, task, period_steps, reobserve, perturbation=None):
    """The episode's task planned on `objects` and executed in `world` (world_execution.run_in_world)."""
    return run_in_world(
        session,
        world,
        objects,
        scene.table_height_m,
        target_index,
        task,
        GOALS[task],
        TOLERANCE_M,
        period_steps,
        reobserve,
        perturbation,
    )


def run_method(
    method,
    scene,
    target_index,
    frame,
    task,
    config,
    twin_timestep_s,
    period_steps,
    tracker="perfect",
    seed=0,
    reconstruction_settings: dict | None = None,
    robust_worlds: int = 0,
) -> dict:
    started = time.perf_counter()
    row = {"method": method}
    try:
        if method == GROUND_TRUTH:
            objects = ground_truth_objects(scene)
        else:
            objects = reconstructed_objects(method, frame, reconstruction_settings)
    except Exception as error:  # a missing checkpoint makes the method unavailable; other errors fail it
        if type(error).__name__ in ("CheckpointError", "FileNotFoundError", "ImportError", "ModuleNotFoundError"):
            return row | {"success": False, "unavailable": f"{type(error).__name__}: {error}"}
        return row | {"success": False, "failure": f"reconstruction failed: {type(error).__name__}: {error}"}
    row["reconstruct_s"] = time.perf_counter() - started
    reobserve = reobservation(tracker, objects, frame, seed) if period_steps > 0 else None
    session = ManipulationSession(config, twin_timestep_s)
    world = SimWorld(scene, robot_arm=True)
    try:
        run = run_task(session, world, objects, scene, target_index, task, period_steps, reobserve)
        outcome = run.outcome
        row.update(
            predicted_success=bool(outcome.success),
            predicted_error_m=outcome.final_error_m,
            plan_message=outcome.message,
            twin_objects=outcome.twin_objects,
            observations=run.observations,
        )
        if reobserve is not None:
            row |= {"poses_fitted": reobserve.fitted, "poses_kept": reobserve.kept}
        if outcome.result is not None and len(outcome.result.step_ms):
            row["mppi_step_ms"] = median(outcome.result.step_ms)
            row["plan_steps"] = len(outcome.result.times_s)
        if outcome.result is not None and outcome.result.replays.twins:
            row["twin_replays"] = [outcome.result.replays.met, outcome.result.replays.twins]
        reward = getattr(session.planner, "_last_reward", None)
        if getattr(reward, "grasp_site_moved", False):
            row["grasp_site_moved"] = True
        if task == TASK_REARRANGE and reward is not None and not isinstance(reward, GraspReward):
            row["pushed_ungraspable"] = True
        if session.twin is not None:
            row["target_stability_m"] = target_stability_m(session, target_index + 1, objects, scene.table_height_m)
        if outcome.planned and robust_worlds > 0:
            if period_steps > 0:
                row["robust"], row["robust_notes"] = closed_loop_robust(
                    objects,
                    scene,
                    target_index,
                    frame,
                    task,
                    config,
                    twin_timestep_s,
                    period_steps,
                    tracker,
                    robust_worlds,
                    seed,
                )
            else:
                row["robust"] = replayed_robust(scene, target_index, task, outcome.result, robust_worlds, seed)
    finally:
        session.close()
        world.close()
    if not run.outcome.planned:
        if run.outcome.infeasible:
            row["infeasible"] = True
        return row | {"success": False, "failure": run.outcome.message, "seconds": time.perf_counter() - started}
    return row | {"success": bool(run.success), "error_m": run.error_m, "seconds": time.perf_counter() - started}


def perturbation_draws(scene, worlds: int, seed: int):
    """The episode's perturbed worlds' draws (seeded by the episode: every method meets the same worlds)."""
    return [
        draw(WorldPerturbation(), len(scene.objects), np.random.default_rng([seed, 7919, k])) for k in range(worlds)
    ]


def closed_loop_robust(
    objects, scene, target_index, frame, task, config, twin_timestep_s, period_steps, tracker, worlds: int, seed: int
) -> tuple[list[bool], list[str]]:
    """(whether the method, planning again from its own twin of the view and executing closed loop,
    meets the task in each of `worlds` perturbed worlds; per world, the plan's message and the
    target's final error in the world)."""
    met, notes = [], []
    for sample in perturbation_draws(scene, worlds, seed):
        session = ManipulationSession(config, twin_timestep_s)
        world = perturbed_world(scene, sample)
        try:
            reobserve = reobservation(tracker, objects, frame, seed)
            run = run_task(session, world, objects, scene, target_index, task, period_steps, reobserve, sample)
            met.append(bool(run.outcome.planned and run.success))
            error = f"; world error {run.error_m:.3f} m" if run.outcome.planned else ""
            notes.append(f"{run.outcome.message}{error}")
        finally:
            session.close()
            world.close()
    return met, notes


def replayed_robust(scene, target_index: int, task: str, result, worlds: int, seed: int) -> list[bool]:
    """Whether the plan's controls, replayed open loop, meet the task in each of `worlds` perturbed worlds."""
    met = []
    for sample in perturbation_draws(scene, worlds, seed):
        world = perturbed_world(scene, sample)
        try:
            body = world.object_ids[target_index]
            start = world.data.xipos[body].copy()
            execute_perturbed(world, result.times_s, result.joint_positions, sample)
            world.execute(np.array([HOLD_AFTER_S]), result.joint_positions[-1:])
            ok, _ = task_outcome(task, start, world.data.xipos[body].copy(), GOALS[task], TOLERANCE_M)
            met.append(bool(ok))
        finally:
            world.close()
    return met


# The planner as benchmarked: a fixed path count per step (real-time adaptation would tie the
# outcomes to the machine's load).
BENCH_PLANNER = PlannerConfig(realtime_factor=0.0)

RESULT_PACKAGES = ("arm_core", "arm_sim", "arm_reconstruction", "arm_planner", "arm_benchmarks")


def result_key(settings: dict) -> str:
    """Run key of the rows: the settings, the checkpoints of settings["methods"] and RESULT_PACKAGES' source."""
    variants = {METHODS[m][0] for m in settings.get("methods", ()) if m in METHODS}
    return run_key(settings, [default_checkpoint_path(v) for v in sorted(variants)], RESULT_PACKAGES)


def load_done(path: pathlib.Path, key: str) -> dict:
    """(episode, method) -> row for the rows of run `key`; rows of other runs go to episodes.stale.jsonl."""
    done, stale = {}, []
    if path.exists():
        for line in path.read_text().splitlines():
            if line.strip():
                row = json.loads(line)
                if row.get("method") in GROUND_TRUTH_ALIASES:  # older files: "ground_truth"
                    row["method"] = GROUND_TRUTH
                if row.get("run_key") == key:
                    done[(row["episode"], row["method"])] = row
                else:
                    stale.append(line)
    if stale:
        stale_path = path.with_name("episodes.stale.jsonl")
        with stale_path.open("a") as sink:
            sink.write("\n".join(stale) + "\n")
        path.write_text("".join(json.dumps(row) + "\n" for row in done.values()))
        print(f"[bench_manip] {len(stale)} rows from another run (code or settings changed) moved to {stale_path}")
    return done


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes", type=int, default=33, help="scenes (each planned by every method)")
    parser.add_argument(
        "--full",
        action="store_true",
        help="paper size: 3 scenes per target x task x visibility bin (2574 with 26 targets)",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="results/manip")
    parser.add_argument("--objects", default=None, help="folder of target meshes (.obj/.stl/.ply, metres)")
    parser.add_argument("--methods", nargs="+", default=list(DEFAULT_METHODS))
    parser.add_argument("--tasks", nargs="+", default=list(TASKS), choices=list(TASKS))
    parser.add_argument(
        "--only-tasks",
        nargs="+",
        default=None,
        choices=list(TASKS),
        help="run only these tasks' episodes of the --tasks design (same scenes as the full run)",
    )
    labels = [bin_label(b) for b in BINS]
    parser.add_argument(
        "--bins", nargs="+", default=labels, choices=labels, metavar="BIN", help="visible-fraction bins to run"
    )
    parser.add_argument("--target-scale", type=float, default=0.8, help="scale of the 8 cm nominal targets")
    parser.add_argument("--twin-timestep", type=float, default=0.01, help="twin physics step, s")
    parser.add_argument(
        "--observe-period",
        type=float,
        default=0.1,
        help="closed loop: the twin observes the world's state every this many seconds (0: open loop, the paper's)",
    )
    parser.add_argument(
        "--tracker",
        choices=("perfect", "depth"),
        default="perfect",
        help="closed loop: object poses from the true motion (perfect) or fitted to new depth frames (depth)",
    )
    parser.add_argument(
        "--paper-postprocessing",
        action="store_true",
        help="reconstructed meshes without the stable base, joined parts, snapping to the depth and solids of "
        "revolution (closer to the paper's post-processing: intersections removed, convex parts)",
    )
    planner_flags = add_arguments(
        parser, BENCH_PLANNER, [s.name for s in settings_of(BENCH_PLANNER) if s.name != "seed"]
    )
    parser.add_argument("--domain", choices=DOMAINS, default=DEFAULT_DOMAIN, help="visual domain of the scenes")
    parser.add_argument(
        "--robust-worlds", type=int, default=5, help="perturbed worlds each plan is executed in again (0: none)"
    )
    parser.add_argument("--fresh", action="store_true", help="ignore earlier results in --out")
    args = parser.parse_args(argv)
    try:
        args.methods = [benchmark_method(m) for m in args.methods]
    except ValueError as error:
        parser.error(f"{error}, or {GROUND_TRUTH}")
    try:
        config = from_arguments(BENCH_PLANNER, args, planner_flags)
    except ValueError as error:
        parser.error(str(error))

    torch.set_num_threads(2)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    log = out / "episodes.jsonl"
    if args.fresh and log.exists():
        log.unlink()
    target_pool = object_pool(args.objects, split="heldout", seed=args.seed)
    distractor_pool = object_pool(None, split="heldout", seed=args.seed + 1)
    n = args.episodes
    if args.full:
        targets = max(len(target_pool), 26 if args.objects is None else len(target_pool))
        n = 3 * targets * len(args.tasks) * len(args.bins)
    episodes = plan_episodes(n, args.tasks, [labels.index(b) for b in args.bins], args.seed)
    run_tasks = args.tasks
    if args.only_tasks:
        run_tasks = [t for t in args.tasks if t in args.only_tasks]
        episodes = [e for e in episodes if e.task in run_tasks]
    period_steps = int(round(args.observe_period / config.mppi.control_dt_s))
    settings = {
        "episodes": n,
        "seed": args.seed,
        "methods": args.methods,
        "tasks": args.tasks,
        "bins": args.bins,
        "target_scale": args.target_scale,
        "twin_timestep_s": args.twin_timestep,
        "observe_period_s": args.observe_period,
        "objects": args.objects or "procedural heldout categories",
        "domain": args.domain,
        "robust_worlds": args.robust_worlds,
        "planner": changed(config, BENCH_PLANNER),  # the planner's settings that are not BENCH_PLANNER's
    }
    settings |= {  # only when not the default
        name: value
        for name, value, default in (
            ("only_tasks", run_tasks, args.tasks),
            ("tracker", args.tracker, "perfect"),
            ("paper_postprocessing", args.paper_postprocessing, False),
        )
        if value != default
    }
    key = result_key(settings | {"objects": str(pathlib.Path(args.objects).resolve()) if args.objects else None})
    done = load_done(log, key)
    progress = tqdm(
        total=len(episodes) * len(args.methods),
        desc="bench_manip",
        initial=sum(1 for e in episodes for m in args.methods if (e.index, m) in done),
    )
    with log.open("a") as sink:
        for episode in episodes:
            todo = [m for m in args.methods if (episode.index, m) not in done]
            if not todo:
                continue
            base = {"episode": episode.index, "task": episode.task, "bin": bin_label(BINS[episode.bin_index])}
            try:
                scene, target_index, frame, target_name = build_scene(
                    episode, BINS, target_pool, distractor_pool, args.target_scale, domain=args.domain
                )
                scene.friction = (
                    config.object_friction
                )  # the table the plans are executed on (built and viewed at rest)
                base |= {
                    "target": target_name,
                    "visible_fraction": float(frame.visible_fraction[target_index]),
                    "objects": len(scene.objects),
                }
            except RuntimeError as error:
                for method in todo:
                    row = base | {"method": method, "skipped": str(error), "success": False, "run_key": key}
                    sink.write(json.dumps(row) + "\n")
                    done[(episode.index, method)] = row
                    progress.update(1)
                continue
            for method in todo:
                row = base | run_method(
                    method,
                    scene,
                    target_index,
                    frame,
                    episode.task,
                    config,
                    args.twin_timestep,
                    period_steps,
                    args.tracker,
                    episode.seed,
                    PAPER_POSTPROCESSING if args.paper_postprocessing else None,
                    args.robust_worlds,
                )
                row["run_key"] = key
                sink.write(json.dumps(row) + "\n")
                sink.flush()
                done[(episode.index, method)] = row
                progress.update(1)
                progress.set_postfix(method=method, task=episode.task, ok=row["success"])
    progress.close()
    rows = [done[(e.index, m)] for e in episodes for m in args.methods if (e.index, m) in done]
    summary = summarise(rows, args.methods, run_tasks, BINS, len(episodes), args.robust_worlds)
    summary["settings"] = settings | {"run_key": key}
    summary["machine"] = machine_description()
    (out / "summary.json").write_text(json.dumps(json_safe(summary), indent=2, allow_nan=False) + "\n")
    write_plots(rows, summary, args.methods, BINS, out)
    write_report(summary, out)
    print(json.dumps(json_safe({m: round(v["success"], 3) for m, v in summary["methods"].items()})))
    print(f"[bench_manip] wrote {out / 'summary.json'}, {out / 'report.md'} and plots")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
