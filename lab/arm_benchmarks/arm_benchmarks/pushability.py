"""pushability: which push targets can slide at all, by quasi-static physics (the push task's ceiling).

A finger pushing an upright object at height h along direction u slides it only if the push does not
tip it first. Sliding needs a horizontal force mu m g (mu: the object-table friction); tipping about
the base's leading edge needs F h >= m g d, d being the distance from the foot of the centre of mass
to the edge of the base's support polygon along u. So the object slides without tipping only if it
is pushed below h* = d / mu (the friction at the finger and the push's speed only make tipping
easier). For targets drawn as bench_manip draws them (the procedural held-out categories, or
--objects, upright, random yaw), this computes h* along the push task's direction and the share of
targets that can be pushed at the planner's contact height and lower ones, for the simulator's
friction and for lower ones; with --measured, beside each category the ground-truth meshes' push
success recorded in bench_manip's episodes.jsonl files. No simulation: the centre of mass is that
of the convex parts at the simulator's uniform density, the support polygon the hull of the
vertices within 1 mm of the bottom.

Writes OUT/summary.json and OUT/hstar.png.
"""

from __future__ import annotations

import argparse
import json
import pathlib

import numpy as np
from scipy.spatial import ConvexHull, QhullError
from tqdm import tqdm

from arm_benchmarks.bench_manip import GOALS
from arm_benchmarks.methods import GROUND_TRUTH
from arm_benchmarks.stats import json_safe, median, wilson_interval
from arm_planner.planner import PlannerConfig
from arm_planner.tasks import TASK_PUSH
from arm_sim.objects import object_pool
from arm_sim.scenes import random_rotation
from arm_sim.world import SLIDING_FRICTION

BASE_BAND_M = 0.001
CONTACT_HEIGHTS_M = (0.006, 0.012, 0.018)
FRICTIONS = (0.3, 0.5, SLIDING_FRICTION)


def centre_of_mass(model) -> np.ndarray:
    """Centre of mass (object frame, m) at uniform density: volume-weighted over the convex parts
    (as MuJoCo computes it from the geoms), else the mesh's."""
    parts = model.convex_parts or [model.mesh]
    volumes = np.array([abs(p.volume) for p in parts])
    centres = np.array([p.center_mass for p in parts])
    return volumes @ centres / volumes.sum()


def tip_free_height(vertices_world: np.ndarray, com_world: np.ndarray, direction_xy: np.ndarray, friction: float):
    """h* (m above the base) below which a push along direction_xy slides the object rather than
    tipping it: d / friction, d the distance from the centre of mass's foot to the edge of the support
    polygon (hull of the vertices within BASE_BAND_M of the lowest) along the direction. 0 when the
    foot lies outside the polygon or the base is a point or a line."""
    bottom = vertices_world[:, 2].min()
    base = vertices_world[vertices_world[:, 2] <= bottom + BASE_BAND_M, :2]
    try:
        hull = ConvexHull(base)
    except (QhullError, ValueError):
        return 0.0
    normals, offsets = hull.equations[:, :2], hull.equations[:, 2]  # n . x + offset <= 0 inside
    foot = com_world[:2]
    if np.any(normals @ foot + offsets > 1e-9):
        return 0.0
    u = direction_xy / np.linalg.norm(direction_xy)
    along = normals @ u
    ahead = along > 1e-12
    distance = float(np.min(-(normals[ahead] @ foot + offsets[ahead]) / along[ahead]))
    return distance / friction


def measured_push_success(paths) -> dict[str, list[int]]:
    """category -> [successes, episodes] of the ground-truth meshes' push episodes in bench_manip
    episodes.jsonl files (the category is the target's name up to its 8-hex-digit suffix)."""
    counts: dict[str, list[int]] = {}
    for path in paths:
        for line in pathlib.Path(path).read_text().splitlines():
            row = json.loads(line)
            if row.get("task") != TASK_PUSH or row.get("method") != GROUND_TRUTH or "target" not in row:
                continue
            category = str(row["target"]).rsplit("_", 1)[0]
            entry = counts.setdefault(category, [0, 0])
            entry[0] += bool(row.get("success"))
            entry[1] += 1
    return counts


def measure(samples: int, seed: int, objects: str | None, measured=()) -> dict:
    pool = object_pool(objects, split="heldout", seed=seed)
    direction = np.asarray(GOALS[TASK_PUSH][:2], dtype=float)
    rng = np.random.default_rng([seed, 24])
    rows = []
    for _ in tqdm(range(samples), desc="pushability", unit="target"):
        model = pool.sample(rng)
        rotation = random_rotation(rng, 1.0)
        vertices = np.concatenate([p.vertices for p in (model.convex_parts or [model.mesh])]) @ rotation.T
        com = rotation @ centre_of_mass(model)
        com_height = float(com[2] - vertices[:, 2].min())
        rows.append(
            {
                "category": model.category,
                "com_height_m": com_height,
                "h_star_m": {f"{mu:g}": tip_free_height(vertices, com, direction, mu) for mu in FRICTIONS},
            }
        )
    planner_height = PlannerConfig().push_contact_height_m
    shares = {}
    for mu in FRICTIONS:
        key = f"{mu:g}"
        h_star = np.array([r["h_star_m"][key] for r in rows])
        shares[key] = {}
        for h in sorted({*CONTACT_HEIGHTS_M, planner_height}):
            n = int(np.sum(h_star > h))
            low, high = wilson_interval(n, len(rows))
            shares[key][f"{h:g}"] = {"pushable": n / len(rows), "ci90": [low, high]}
    by_category = {}
    recorded = measured_push_success(measured)
    for category in sorted({r["category"] for r in rows}):
        chosen = [r for r in rows if r["category"] == category]
        h_star = np.array([r["h_star_m"][f"{SLIDING_FRICTION:g}"] for r in chosen])
        by_category[category] = {
            "n": len(chosen),
            "h_star_m_median": median(h_star),
            "pushable_at_planner_height": float(np.mean(h_star > planner_height)),
            "com_height_m_median": median([r["com_height_m"] for r in chosen]),
        }
        if category in recorded:
            successes, n = recorded[category]
            by_category[category]["measured_ground_truth_push"] = {"success": successes / n, "episodes": n}
    return {
        "samples": samples,
        "seed": seed,
        "objects": objects or "procedural held-out categories",
        "push_direction_xy": direction.tolist(),
        "simulator_friction": SLIDING_FRICTION,
        "planner_contact_height_m": planner_height,
        "pushable_share": shares,
        "by_category": by_category,
        "measured_from": [str(p) for p in measured],
        "h_star_m": [r["h_star_m"] for r in rows],
    }


def plot(summary: dict, path: pathlib.Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(6, 3.5))
    for mu in FRICTIONS:
        h_star = np.sort([100 * r[f"{mu:g}"] for r in summary["h_star_m"]])
        axis.plot(h_star, 1.0 - np.arange(len(h_star)) / len(h_star), label=f"friction {mu:g}")
    axis.axvline(100 * summary["planner_contact_height_m"], color="k", ls="--", lw=1, label="planner's contact")
    axis.set_xlim(0, 8)
    axis.set_xlabel("contact height h (cm)")
    axis.set_ylabel("share of targets with h* > h")
    axis.set_title("push targets that slide rather than tip (quasi-static)")
    axis.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--samples", type=int, default=300, help="targets drawn")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--objects", default=None, help="folder of target meshes (default: procedural held-out)")
    parser.add_argument("--measured", nargs="*", default=(), help="bench_manip episodes.jsonl files to compare")
    parser.add_argument("--out", default="results/pushability")
    args = parser.parse_args(argv)
    if args.samples < 1:
        parser.error("--samples must be >= 1")
    summary = measure(args.samples, args.seed, args.objects, args.measured)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(json_safe(summary), indent=1))
    plot(summary, out / "hstar.png")
    shares = summary["pushable_share"]
    for mu, by_height in shares.items():
        text = ", ".join(f"{100 * float(h):.1f} cm {v['pushable']:.2f}" for h, v in by_height.items())
        print(f"[pushability] friction {mu}: pushable at {text}")
    for category, row in summary["by_category"].items():
        seen = row.get("measured_ground_truth_push")
        text = f", ground truth pushed {seen['success']:.2f} of {seen['episodes']}" if seen else ""
        share = row["pushable_at_planner_height"]
        print(f"[pushability] {category}: pushable at the planner's height {share:.2f}{text}")
    print(f"[pushability] wrote {out / 'summary.json'}, {out / 'hstar.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
