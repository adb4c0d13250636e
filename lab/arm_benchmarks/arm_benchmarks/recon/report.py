"""bench_recon's report.md."""

from __future__ import annotations

import pathlib

import numpy as np

from arm_benchmarks.methods import GROUND_TRUTH
from arm_benchmarks.recon.config import OCCLUDED_VISIBILITY, TARGET_RUNTIME_S, VISIBILITY_BINS
from arm_benchmarks.recon.summary import bin_label
from arm_sim.objects import HELDOUT_CATEGORIES


def _shown(key: str, value) -> str:
    if value is None:
        return "-"
    if key == "priors_earn_their_place":
        (arm_c, cs_c), (arm_s, cs_s) = value["chamfer_m"], value["stable_fraction"]
        return f"Chamfer {arm_c * 1000:.2f} vs {cs_c * 1000:.2f} mm, stable {arm_s:.3f} vs {cs_s:.3f}"
    if isinstance(value, dict):
        return ", ".join(f"{k}: {'-' if v is None else 'yes' if v else 'no'}" for k, v in value.items())
    return f"{value * 1000:.2f} mm" if key.startswith("arm_chamfer_m") else f"{value:.3f}"


def _fmt(value, scale=1.0, digits=3, none="-") -> str:
    return none if value is None or not np.isfinite(value) else f"{value * scale:.{digits}f}"


def write_report(summary: dict, path: pathlib.Path, figures: list[str]) -> None:
    cfg, methods = summary["config"], summary["methods"]
    ok = [n for n, m in methods.items() if m["status"] == "ok"]
    pool = cfg["objects"] or "procedural held-out categories (" + ", ".join(HELDOUT_CATEGORIES) + ")"
    seg = (
        "ground-truth instance labels"
        if cfg["segmentation"] == "ground-truth"
        else "instance labels predicted by arm_segmentation.segment (true objects matched at mask IoU > 0.5)"
    )
    view = (
        "the first random view of the paper's camera distribution that shows an object"
        if cfg["view"] == "random"
        else (
            f"of {cfg['view_candidates']} random views of the paper's camera distribution, the one with the most "
            f"evaluated objects less than {OCCLUDED_VISIBILITY:.0%} visible, to populate the low-visibility bins: "
            "the overall means weigh occluded objects more than random views would; the per-bin results do not "
            "depend on it"
        )
    )
    lines = [
        "# Reconstruction benchmark: ARM against its baselines (paper Figure 4)",
        "",
        f"{summary['scenes']} cluttered scenes (seed {cfg['seed']}, {cfg['min_objects']}-{cfg['max_objects']} objects, "
        f"pool: {pool}), one 640x480 view each ({view}; depth noise "
        f"{'on' if cfg['depth_noise'] else 'off'}), {seg}. {summary['objects']} objects evaluated (those showing >= "
        f"{cfg['min_visible_pixels']} pixels with depth); {summary['objects_matched']} matched.",
        "",
        "**Chamfer distance** (metres, reported in mm): N = "
        f"{cfg['chamfer_samples']} points sampled uniformly by area on the reconstructed surface (A) and on the "
        "true surface (B); CD = 0.5 * (mean over a in A of min over b in B of |a - b| + mean over b in B of min over "
        "a in A of |a - b|). **IoU**: voxel centres inside each closed mesh in a "
        f"{cfg['iou_resolution']}^3 cube enclosing both. **Stability**: each method's objects of a view are built "
        "into a MuJoCo scene from convex parts as the planner's twin builds them (table, no robot), simulated "
        f"{cfg['settle_s']:g} s under gravity (step {cfg['physics_timestep_s']:g} s, the twin's); stable = the "
        f"object's centre of mass moved < {cfg['stable_threshold_m'] * 100:g} cm. The true meshes go through the same "
        "decomposition and scene builder (ground-truth row). An object a method left empty counts as IoU 0 and not "
        "stable and is left out of that method's Chamfer mean (column 'empty'). Intervals: 90% (bootstrap for means, "
        "Wilson for fractions).",
        "",
        "## Overall",
        "",
        "| method | objects | empty | Chamfer mm (90% CI) | median mm | normal consistency | IoU "
        "| stable fraction (90% CI) | displacement cm, median / mean | s/scene |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name in ok:
        m = methods[name]
        low, high = (_fmt(v, 1000, 2) for v in m.get("chamfer_m_ci90", [None, None]))
        chamfer = "-" if m["chamfer_m"] is None else f"{m['chamfer_m'] * 1000:.2f} ({low}-{high})"
        stable = (
            "-"
            if m["stable_fraction"] is None
            else f"{m['stable_fraction']:.3f} ({_fmt(m['stable_ci90'][0])}-{_fmt(m['stable_ci90'][1])})"
        )
        moved = f"{_fmt(m['displacement_m_median'], 100, 2)} / {_fmt(m['displacement_m_mean'], 100, 2)}"
        lines.append(
            f"| {name} | {m['n']} | {m['n_empty']} | {chamfer} | {_fmt(m.get('chamfer_m_median'), 1000, 2)} "
            f"| {_fmt(m.get('normal_consistency'))} | {_fmt(m['iou'])} | {stable} | {moved} "
            f"| {_fmt(m['seconds_per_scene'], 1, 1)} |"
        )
    sim_parts = methods.get(GROUND_TRUTH, {}).get("simulator_parts")
    if sim_parts and sim_parts["stable_fraction"] is not None:
        low, high = (_fmt(v) for v in sim_parts["stable_ci90"])
        lines.append(
            f"\nFor scale: the true meshes with the simulator's own convex parts (not re-decomposed by the "
            f"pipeline) are stable in {sim_parts['stable_fraction']:.3f} ({low}-{high}) of cases; the gap to "
            "the ground-truth row is what the pipeline's convex decomposition costs."
        )
    for name, m in methods.items():
        if m["status"] == "skipped":
            lines.append(f"\n**{name}: skipped** ({m['reason']})")
    labels = [bin_label(b) for b in VISIBILITY_BINS]
    counts = " | ".join(str(summary["objects_by_visibility"][b]) for b in labels)
    for title, key, scale, digits in (
        ("Chamfer distance (mm) by visible fraction", "chamfer_m", 1000, 2),
        ("Volumetric IoU by visible fraction", "iou", 1, 3),
        ("Stable fraction by visible fraction", "stable_fraction", 1, 3),
    ):
        lines += [
            "",
            f"## {title}",
            "",
            "| method | " + " | ".join(labels) + " |",
            "|---|" + "---|" * len(labels),
            f"| objects | {counts} |",
        ]
        for name in ok:
            if key != "stable_fraction" and name == GROUND_TRUTH:
                continue
            bins = methods[name]["by_visibility"]
            lines.append(f"| {name} | " + " | ".join(_fmt(bins[b][key], scale, digits) for b in labels) + " |")
    paired = summary["arm_vs_baseline_paired_chamfer"]
    if paired:
        lines += [
            "",
            "## arm vs baseline, paired (objects both reconstructed)",
            "",
            "| visibility | objects | baseline mm | arm mm | reduction |",
            "|---|---|---|---|---|",
        ]
        for label, p in [("all", paired), *paired["by_visibility"].items()]:
            lines.append(
                f"| {label} | {p['n']} | {_fmt(p['baseline'], 1000, 2)} | {_fmt(p['arm'], 1000, 2)} "
                f"| {_fmt(p['reduction'], 100, 1)}{'%' if p['reduction'] is not None else ''} |"
            )
    lines += ["", "## Targets (issue 23)", "", "| target | measured | met |", "|---|---|---|"]
    names = {
        "arm_chamfer_reduction_vs_baseline": ">= 28% lower Chamfer than baseline",
        "arm_lower_chamfer_every_bin": "lower Chamfer than baseline in every visibility bin",
        "arm_chamfer_m": "arm Chamfer <= 5.0 mm",
        "arm_chamfer_m_visible_0.8_1.0": "arm Chamfer <= 4.0 mm at visible fraction 0.8-1.0",
        "arm_iou": "arm IoU >= 0.5",
        "arm_normal_consistency": "arm normal consistency >= 0.85",
        "priors_earn_their_place": "arm beats arm-c-s on Chamfer or stable (disjoint 90 % CIs), no worse on the rest",
        "arm_stable_fraction": "arm stable fraction >= 0.9",
        "arm_stable_gap_to_ground_truth": "arm within 3 points of ground truth's stable fraction",
    }
    for key, t in summary["targets"].items():
        lines.append(
            f"| {names[key]} | {_shown(key, t['value'])} | {'-' if t['met'] is None else 'yes' if t['met'] else 'no'} |"
        )
    run = summary.get("run", {})
    if run:
        runtime_met = run["scenes_computed"] == summary["scenes"] and run["wall_s"] <= TARGET_RUNTIME_S
        lines.append(
            f"| default run under 15 min on this machine | {run['wall_s'] / 60:.1f} min wall, "
            f"{run['cpu_s'] / 60:.1f} min process CPU "
            f"({run['scenes_computed']} of {summary['scenes']} scenes computed in this run) "
            f"| {'yes' if runtime_met else 'no' if run['scenes_computed'] == summary['scenes'] else 'n/a'} |"
        )
        lines += [
            "",
            f"Machine: {run['machine']}, {run['cpu_count']} CPUs, torch threads {cfg['threads']}, "
            f"load average {run['load_average']:.1f} at the end (the machine is shared). Sum of per-scene "
            f"compute over all scenes (cached included): {summary['scene_compute_s'] / 60:.1f} min.",
        ]
    lines += ["", "## Figures", ""] + [f"![{f}]({f})" for f in figures]
    path.write_text("\n".join(lines) + "\n")
