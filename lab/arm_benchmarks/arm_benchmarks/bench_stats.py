"""Success rates with 90% Wilson intervals (arm_benchmarks.stats), plots and the report of bench_manip."""

from __future__ import annotations

import math
import pathlib

import matplotlib
import matplotlib.pyplot as plt
import numpy as np

from arm_benchmarks.methods import GROUND_TRUTH
from arm_benchmarks.stats import median, rate, wilson_interval

matplotlib.use("Agg")

# The paper's eleven visibility levels: [0, 0.1), ..., [0.9, 1.0) and unoccluded (1.0).
BINS = tuple((round(0.1 * i, 1), round(0.1 * (i + 1), 1)) for i in range(10)) + ((0.995, 1.01),)
STABILITY_BINS_M = (0.0, 0.005, 0.02, 0.05, float("inf"))


def bin_label(bounds) -> str:
    lo, hi = bounds
    return "1.0" if lo >= 0.99 else f"{lo:.1f}-{hi:.1f}"


def _rate(rows) -> dict:
    n = len(rows)
    k = sum(bool(r["success"]) for r in rows)
    low, high = wilson_interval(k, n)
    return {"rate": rate(k, n), "ci90": [low, high], "n": n}


def counted(rows) -> list[dict]:
    """Rows that count: a scene existed and the method could run."""
    return [r for r in rows if "skipped" not in r and "unavailable" not in r]


def infeasible_episodes(rows) -> set:
    """Episodes the robot cannot do at all, as judged on the true meshes: ground truth's planner refused
    them (the target or goal out of reach, or the target too wide for the gripper every way)."""
    return {r["episode"] for r in rows if r["method"] == GROUND_TRUTH and r.get("infeasible")}


def _robust_rate(rows, worlds: int) -> dict:
    """The share of the perturbed executions that met the task (a row without a plan: none did)."""
    executions = [ok for r in rows for ok in r.get("robust", [False] * worlds)]
    k, n = sum(executions), len(executions)
    low, high = wilson_interval(k, n)
    return {"rate": rate(k, n), "ci90": [low, high], "n": n}


def summarise(rows, methods, tasks, bins, episodes: int, robust_worlds: int = 0) -> dict:
    summary = {"methods": {}, "episodes": episodes, "confidence": 0.9, "robust_worlds": robust_worlds}
    infeasible = infeasible_episodes(rows)
    judged = any(r["method"] == GROUND_TRUTH for r in rows)
    for method in methods:
        mine = [r for r in rows if r["method"] == method]
        unavailable = sorted({r["unavailable"] for r in mine if "unavailable" in r})
        mine = counted(mine)
        overall = _rate(mine)
        by_task = {t: _rate([r for r in mine if r["task"] == t]) for t in tasks}
        by_bin = {bin_label(b): _rate([r for r in mine if r["bin"] == bin_label(b)]) for b in bins}
        summary["methods"][method] = {
            "success": overall["rate"],
            "success_ci90": overall["ci90"],
            "n": overall["n"],
            "by_task": {t: v["rate"] for t, v in by_task.items()},
            "by_task_ci90": {t: v["ci90"] for t, v in by_task.items()},
            "by_task_n": {t: v["n"] for t, v in by_task.items()},
            "by_visibility": {b: v["rate"] for b, v in by_bin.items()},
            "by_visibility_ci90": {b: v["ci90"] for b, v in by_bin.items()},
            "by_visibility_n": {b: v["n"] for b, v in by_bin.items()},
            "predicted_success": _rate([{"success": r.get("predicted_success", False)} for r in mine])["rate"],
            "median_mppi_step_ms": median([r["mppi_step_ms"] for r in mine if "mppi_step_ms" in r]),
        }
        if judged:
            feasible = _rate([r for r in mine if r["episode"] not in infeasible])
            summary["methods"][method] |= {
                "feasible_success": feasible["rate"],
                "feasible_success_ci90": feasible["ci90"],
                "feasible_n": feasible["n"],
            }
        if robust_worlds:
            robust = _robust_rate(mine, robust_worlds)
            robust_task = {t: _robust_rate([r for r in mine if r["task"] == t], robust_worlds) for t in tasks}
            robust_bin = {
                bin_label(b): _robust_rate([r for r in mine if r["bin"] == bin_label(b)], robust_worlds) for b in bins
            }
            summary["methods"][method] |= {
                "robust_success": robust["rate"],
                "robust_success_ci90": robust["ci90"],
                "robust_n": robust["n"],
                "robust_by_task": {t: v["rate"] for t, v in robust_task.items()},
                "robust_by_task_ci90": {t: v["ci90"] for t, v in robust_task.items()},
                "robust_by_task_n": {t: v["n"] for t, v in robust_task.items()},
                "robust_by_visibility": {b: v["rate"] for b, v in robust_bin.items()},
                "robust_by_visibility_ci90": {b: v["ci90"] for b, v in robust_bin.items()},
                "robust_by_visibility_n": {b: v["n"] for b, v in robust_bin.items()},
            }
        if unavailable:
            summary["methods"][method]["unavailable"] = unavailable
    if judged:
        summary["infeasible_episodes"] = sorted(infeasible)
    summary["targets"] = _targets(summary)
    return summary


def _targets(summary) -> dict:
    methods = summary["methods"]

    def success(m):
        return methods.get(m, {}).get("success", float("nan"))

    checks = {"ground_truth_success": success(GROUND_TRUTH)}
    if "feasible_success" in methods.get(GROUND_TRUTH, {}):
        checks["ground_truth_feasible_success"] = methods[GROUND_TRUTH]["feasible_success"]
    if "arm" in methods and "baseline" in methods and success("baseline") > 0:
        checks["arm_over_baseline"] = success("arm") / success("baseline")
    if "arm" in methods:
        vis = methods["arm"]["by_visibility"]
        if vis.get("1.0", 0) and not math.isnan(vis.get("1.0", float("nan"))):
            checks["arm_vis_0.1-0.2_over_unoccluded"] = vis.get("0.1-0.2", float("nan")) / vis["1.0"]
    return checks


def write_plots(rows, summary, methods, bins, out: pathlib.Path) -> None:
    methods = [m for m in methods if summary["methods"][m]["n"] > 0] or list(methods)
    labels = [bin_label(b) for b in bins]
    x = np.arange(len(labels))
    fig, ax = plt.subplots(figsize=(9, 4.5))
    width = 0.8 / max(len(methods), 1)
    for k, method in enumerate(methods):
        stats = summary["methods"][method]
        rates = np.array([stats["by_visibility"][b] for b in labels], dtype=float)
        ci = np.array([stats["by_visibility_ci90"][b] for b in labels], dtype=float)
        err = np.abs(np.stack([rates - ci[:, 0], ci[:, 1] - rates]))
        ax.bar(
            x + (k - (len(methods) - 1) / 2) * width,
            np.nan_to_num(rates),
            width,
            yerr=np.nan_to_num(err),
            capsize=2,
            label=method,
        )
    ax.set_xticks(x, labels, rotation=45)
    ax.set_xlabel("target visible fraction")
    ax.set_ylabel("success rate (90% CI)")
    ax.set_ylim(0, 1.05)
    ax.legend()
    ax.set_title("Manipulation success vs target visibility")
    fig.tight_layout()
    fig.savefig(out / "success_vs_visibility.png", dpi=120)
    plt.close(fig)

    edges = STABILITY_BINS_M
    names = [
        f"<{edges[i + 1] * 100:.1f} cm" if np.isfinite(edges[i + 1]) else f">={edges[i] * 100:.1f} cm"
        for i in range(len(edges) - 1)
    ]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for k, method in enumerate(methods):
        mine = [r for r in counted(rows) if r["method"] == method and np.isfinite(r.get("target_stability_m", np.nan))]
        rates, errs = [], []
        for i in range(len(edges) - 1):
            sel = [r for r in mine if edges[i] <= r["target_stability_m"] < edges[i + 1]]
            k = sum(bool(r["success"]) for r in sel)
            p, (lo, hi) = rate(k, len(sel)), wilson_interval(k, len(sel))
            rates.append(p)
            errs.append((p - lo, hi - p))
        rates = np.array(rates, dtype=float)
        errs = np.nan_to_num(np.array(errs, dtype=float).T)
        w = 0.8 / max(len(methods), 1)
        ax.bar(
            np.arange(len(names)) + (k - (len(methods) - 1) / 2) * w,
            np.nan_to_num(rates),
            w,
            yerr=errs,
            capsize=2,
            label=method,
        )
    ax.set_xticks(np.arange(len(names)), names)
    ax.set_xlabel("target displacement when its reconstruction settles (lower = more stable)")
    ax.set_ylabel("success rate (90% CI)")
    ax.set_ylim(0, 1.05)
    ax.legend()
    ax.set_title("Manipulation success vs reconstructed target stability")
    fig.tight_layout()
    fig.savefig(out / "success_vs_stability.png", dpi=120)
    plt.close(fig)


def _fmt(rate, ci, n) -> str:
    if n == 0 or rate is None or (isinstance(rate, float) and math.isnan(rate)):
        return "-"
    return f"{rate:.2f} [{ci[0]:.2f}, {ci[1]:.2f}] (n={n})"


def _robust_lines(summary) -> list[str]:
    """The report's robust-success tables: per method and task, and per visibility bin."""
    methods = summary["methods"]
    first = next(iter(methods.values()))
    lines = [
        "",
        "## Robust success",
        "",
        f"Each method's plan executed again, as in the nominal world, in {summary['robust_worlds']} perturbed worlds "
        "(objects moved <= 5 mm and turned <= 5 deg, friction x0.5-1.5, masses x0.7-1.3, 0-40 ms latency, joints off "
        "<= 0.5 deg): "
        + (
            "closed loop, planned again from the method's twin of the view, which does not know the perturbation"
            if (summary.get("settings", {}).get("observe_period_s") or 0.0) > 0
            else "open loop, the nominal plan's controls replayed"
        )
        + ". The share of those executions that met the task (n: executions).",
        "",
        "| method | nominal | robust | " + " | ".join(first["robust_by_task"]) + " |",
        "|---|---|---|" + "---|" * len(first["robust_by_task"]),
    ]
    for name, m in methods.items():
        cells = [_fmt(m["success"], m["success_ci90"], m["n"])]
        cells.append(_fmt(m["robust_success"], m["robust_success_ci90"], m["robust_n"]))
        cells += [
            _fmt(m["robust_by_task"][t], m["robust_by_task_ci90"][t], m["robust_by_task_n"][t])
            for t in m["robust_by_task"]
        ]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines += ["", "| visible fraction | " + " | ".join(f"{name} robust" for name in methods) + " |"]
    lines.append("|---|" + "---|" * len(methods))
    for b in first["robust_by_visibility"]:
        cells = [
            _fmt(m["robust_by_visibility"][b], m["robust_by_visibility_ci90"][b], m["robust_by_visibility_n"][b])
            for m in methods.values()
        ]
        lines.append(f"| {b} | " + " | ".join(cells) + " |")
    return lines


def write_report(summary, out: pathlib.Path) -> None:
    methods = summary["methods"]
    settings = summary.get("settings", {})
    period = settings.get("observe_period_s") or 0.0
    execution = (
        f"runs closed loop in the ground-truth world (every {period:g} s the twin takes the world's joint "
        "states and the objects' tracked poses, applied to the method's own meshes)"
        if period > 0
        else "runs open loop in the ground-truth world (as in the paper)"
    )
    lines = [
        "# Cluttered manipulation benchmark",
        "",
        f"Episodes (scenes): {summary['episodes']}; every method plans on its own reconstruction of the same "
        f"view and the plan {execution}. Rates with 90% Wilson intervals. 'predicted (twin)': the task met "
        "in the twin when planning ended.",
        "",
        "Settings: " + ", ".join(f"{k}={v}" for k, v in settings.items()),
        "",
        "## Success by method and task",
        "",
        "| method | all | " + " | ".join(next(iter(methods.values()))["by_task"]) + " | predicted (twin) |",
        "|---|---|" + "---|" * len(next(iter(methods.values()))["by_task"]) + "---|",
    ]
    for name, m in methods.items():
        cells = [_fmt(m["success"], m["success_ci90"], m["n"])]
        cells += [_fmt(m["by_task"][t], m["by_task_ci90"][t], m["by_task_n"][t]) for t in m["by_task"]]
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {m['predicted_success']:.2f} |")
        if "unavailable" in m:
            lines.append(f"| {name} unavailable: {'; '.join(m['unavailable'])} |")
    if "infeasible_episodes" in summary:
        lines += [
            "",
            f"Episodes the robot cannot do at all (ground truth's planner refused them: out of reach, or the "
            f"target wider than the open gripper every way): {len(summary['infeasible_episodes'])} "
            f"{summary['infeasible_episodes']}. Success over the others:",
            "",
        ]
        lines += [
            f"- {name}: {_fmt(m['feasible_success'], m['feasible_success_ci90'], m['feasible_n'])}"
            for name, m in methods.items()
        ]
    lines += ["", "## Success by target visibility", ""]
    first = next(iter(methods.values()))
    lines.append("| visible fraction | " + " | ".join(methods) + " |")
    lines.append("|---|" + "---|" * len(methods))
    for b in first["by_visibility"]:
        cells = [
            _fmt(m["by_visibility"][b], m["by_visibility_ci90"][b], m["by_visibility_n"][b]) for m in methods.values()
        ]
        lines.append(f"| {b} | " + " | ".join(cells) + " |")
    if summary.get("robust_worlds"):
        lines += _robust_lines(summary)
    lines += ["", "## Targets", ""]
    for key, value in summary["targets"].items():
        lines.append(f"- {key}: {value:.3f}" if isinstance(value, float) else f"- {key}: {value}")
    lines += ["", "Plots: success_vs_visibility.png, success_vs_stability.png", ""]
    (out / "report.md").write_text("\n".join(lines))
