"""bench_recon's statistics: per method, overall and by visible fraction, the paired arm-baseline
comparison and the issue's targets."""

from __future__ import annotations

import dataclasses

import numpy as np

from arm_benchmarks.methods import GROUND_TRUTH
from arm_benchmarks.recon.config import (
    TARGET_ARM_CHAMFER_M,
    TARGET_ARM_CHAMFER_VISIBLE_M,
    TARGET_ARM_IOU,
    TARGET_CHAMFER_REDUCTION,
    TARGET_NORMAL_CONSISTENCY,
    TARGET_STABLE_FRACTION,
    TARGET_STABLE_GAP,
    VISIBILITY_BINS,
    BenchConfig,
)
from arm_benchmarks.stats import bootstrap_interval, mean, median, none_if_nan, rate, wilson_interval


def bin_label(bounds) -> str:
    return f"{bounds[0]:.1f}-{bounds[1]:.1f}"


def visibility_bin(fraction: float) -> str:
    for lo, hi in VISIBILITY_BINS:
        if lo <= fraction < hi or (hi == VISIBILITY_BINS[-1][1] and fraction >= hi):
            return bin_label((lo, hi))
    return bin_label(VISIBILITY_BINS[0])


def _stats(entries: list[dict], threshold_m: float, geometric: bool) -> dict:
    moved = [e["displacement_m"] for e in entries]
    stable = sum(m is not None and m < threshold_m for m in moved)
    finite = [m for m in moved if m is not None and np.isfinite(m)]
    out = {"n": len(entries), "n_empty": sum(e["empty"] for e in entries)}
    if geometric:
        chamfer = [e["chamfer_m"] for e in entries if e["chamfer_m"] is not None]
        iou = [e["iou"] for e in entries if e["iou"] is not None]
        normals = [e["normal_consistency"] for e in entries if e.get("normal_consistency") is not None]
        out |= {
            "normal_consistency": none_if_nan(mean(normals)),
            "chamfer_m": none_if_nan(mean(chamfer)),
            "chamfer_m_median": none_if_nan(median(chamfer)),
            "chamfer_m_ci90": none_if_nan(bootstrap_interval(chamfer)),
            "n_chamfer": len(chamfer),
            "iou": none_if_nan(mean(iou)),
            "iou_ci90": none_if_nan(bootstrap_interval(iou)),
            "n_iou_undefined": len(entries) - len(iou),
        }
    else:
        out |= {"chamfer_m": None, "normal_consistency": None, "iou": None}
    out |= {
        "stable_fraction": none_if_nan(rate(stable, len(entries))),
        "stable_ci90": none_if_nan(wilson_interval(stable, len(entries))),
        "displacement_m_mean": none_if_nan(mean(finite)),
        "displacement_m_median": none_if_nan(median(finite)),
    }
    return out


def paired_chamfer(rows: list[dict], a: str, b: str, bins=True) -> dict:
    """Chamfer of a and b on the objects both reconstructed: means, relative reduction 1 - a / b."""

    def compare(subset):
        pairs = [
            (r["methods"][a]["chamfer_m"], r["methods"][b]["chamfer_m"])
            for r in subset
            if a in r["methods"]
            and b in r["methods"]
            and r["methods"][a]["chamfer_m"] is not None
            and r["methods"][b]["chamfer_m"] is not None
        ]
        if not pairs:
            return {"n": 0, a: None, b: None, "reduction": None}
        mean_a, mean_b = (mean(v) for v in zip(*pairs, strict=True))
        return {"n": len(pairs), a: mean_a, b: mean_b, "reduction": 1.0 - mean_a / mean_b if mean_b > 0 else None}

    out = compare(rows)
    if bins:
        out["by_visibility"] = {
            bin_label(b): compare([r for r in rows if r["bin"] == bin_label(b)]) for b in VISIBILITY_BINS
        }
    return out


def summarise(results: list[dict], config: BenchConfig, skipped: dict, checkpoints: dict) -> dict:
    rows = [dict(r, bin=visibility_bin(r["visible_fraction"])) for result in results for r in result["rows"]]
    methods = {}
    for name in config.methods:
        if name in skipped:
            methods[name] = {"status": "skipped", "reason": skipped[name]}
            continue
        entries = [r for r in rows if name in r["methods"]]
        geometric = name != GROUND_TRUTH
        stats = _stats([r["methods"][name] for r in entries], config.stable_threshold_m, geometric)
        by_visibility = {}
        for bounds in VISIBILITY_BINS:
            label = bin_label(bounds)
            in_bin = [r["methods"][name] for r in entries if r["bin"] == label]
            by_visibility[label] = _stats(in_bin, config.stable_threshold_m, geometric)
        timings = [s["timing_s"][name] for s in results if name in s["timing_s"]]
        methods[name] = {
            "status": "ok",
            **stats,
            "by_visibility": by_visibility,
            "seconds_per_scene": none_if_nan(mean([t["total_s"] for t in timings])),
        }
        if name in checkpoints:
            methods[name]["checkpoint"] = checkpoints[name]
    ok = {name for name, m in methods.items() if m["status"] == "ok"}
    if GROUND_TRUTH in ok:
        sim_parts = [
            {"empty": False, "displacement_m": r["methods"][GROUND_TRUTH].get("displacement_sim_parts_m")} for r in rows
        ]
        methods[GROUND_TRUTH]["simulator_parts"] = _stats(sim_parts, config.stable_threshold_m, False)
    paired = paired_chamfer(rows, "arm", "baseline") if {"arm", "baseline"} <= ok else None
    summary = {
        "methods": methods,
        "objects": len(rows),
        "scenes": len(results),
        "objects_matched": sum(r["matched"] for r in rows),
        "objects_by_visibility": {bin_label(b): sum(r["bin"] == bin_label(b) for r in rows) for b in VISIBILITY_BINS},
        "arm_vs_baseline_paired_chamfer": paired,
        "config": {k: v for k, v in dataclasses.asdict(config).items()} | {"methods": list(config.methods)},
        "scene_compute_s": float(sum(r["wall_s"] for r in results)),
        "scene_cpu_s": float(sum(r.get("cpu_s", 0.0) for r in results)),
        "confidence": 0.9,
    }
    summary["targets"] = targets(summary)
    return summary


def priors_earn_their_place(arm: dict, no_priors: dict) -> dict:
    """arm against arm-c-s: better on Chamfer or on stable fraction with disjoint 90 % intervals, and
    no worse (mean) on the other."""
    if no_priors.get("status") != "ok" or no_priors.get("chamfer_m") is None:
        return {"value": None, "met": None}
    chamfer_win = arm["chamfer_m_ci90"][1] < no_priors["chamfer_m_ci90"][0]
    stable_win = arm["stable_ci90"][0] > no_priors["stable_ci90"][1]
    chamfer_no_worse = arm["chamfer_m"] <= no_priors["chamfer_m"]
    stable_no_worse = arm["stable_fraction"] >= no_priors["stable_fraction"]
    value = {
        "chamfer_m": [arm["chamfer_m"], no_priors["chamfer_m"]],
        "stable_fraction": [arm["stable_fraction"], no_priors["stable_fraction"]],
    }
    met = (chamfer_win and stable_no_worse) or (stable_win and chamfer_no_worse)
    return {"value": value, "met": bool(met)}


def targets(summary: dict) -> dict:
    """The issue's targets, evaluated on what was measured (None: not measurable in this run)."""
    methods, paired = summary["methods"], summary["arm_vs_baseline_paired_chamfer"]
    out = {}
    if paired and paired["reduction"] is not None:
        out["arm_chamfer_reduction_vs_baseline"] = {
            "value": paired["reduction"],
            "target": TARGET_CHAMFER_REDUCTION,
            "met": paired["reduction"] >= TARGET_CHAMFER_REDUCTION,
        }
        lower = {label: (p["arm"] < p["baseline"]) if p["n"] else None for label, p in paired["by_visibility"].items()}
        out["arm_lower_chamfer_every_bin"] = {"value": lower, "met": all(v is True for v in lower.values())}
    arm, truth = methods.get("arm", {}), methods.get(GROUND_TRUTH, {})
    if arm.get("status") == "ok" and arm.get("chamfer_m") is not None:
        visible = arm["by_visibility"].get("0.8-1.0", {}).get("chamfer_m")
        for name, value, target, below in (
            ("arm_chamfer_m", arm["chamfer_m"], TARGET_ARM_CHAMFER_M, True),
            ("arm_chamfer_m_visible_0.8_1.0", visible, TARGET_ARM_CHAMFER_VISIBLE_M, True),
            ("arm_iou", arm["iou"], TARGET_ARM_IOU, False),
            ("arm_normal_consistency", arm.get("normal_consistency"), TARGET_NORMAL_CONSISTENCY, False),
        ):
            if value is not None:
                out[name] = {"value": value, "target": target, "met": value <= target if below else value >= target}
        out["priors_earn_their_place"] = priors_earn_their_place(arm, methods.get("arm-c-s", {}))
    if arm.get("status") == "ok" and arm["stable_fraction"] is not None:
        out["arm_stable_fraction"] = {
            "value": arm["stable_fraction"],
            "target": TARGET_STABLE_FRACTION,
            "met": arm["stable_fraction"] >= TARGET_STABLE_FRACTION,
        }
        if truth.get("status") == "ok" and truth["stable_fraction"] is not None:
            gap = truth["stable_fraction"] - arm["stable_fraction"]
            out["arm_stable_gap_to_ground_truth"] = {
                "value": gap,
                "target": TARGET_STABLE_GAP,
                "met": gap <= TARGET_STABLE_GAP,
            }
    return out
