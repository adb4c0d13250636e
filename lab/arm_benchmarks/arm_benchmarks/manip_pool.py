"""bench_manip_pool: one summary of a bench_manip design from runs that each ran some of its tasks.

A planner change that touches one task is re-measured with `bench_manip --only-tasks ...` on the same
design (episodes, seed, bins, tasks, objects); this pools the runs' tasks into one summary.json,
report.md and plots, with the same statistics as bench_manip. A run made with --only-tasks gives its
tasks, a full run the others; only rows of each run's own key count.

    bench_manip_pool results/manip99_grasp results/manip99_push results/manip99_rearrange --out results/manip99_pooled
"""

from __future__ import annotations

import argparse
import json
import pathlib

from arm_benchmarks.bench_stats import BINS, summarise, write_plots, write_report
from arm_benchmarks.stats import json_safe

# Settings that define the design: runs pooled together must agree on them (observe_period_s: closed
# loop every so many seconds, 0 = open loop).
DESIGN_KEYS = ("episodes", "seed", "tasks", "bins", "objects", "domain", "target_scale", "observe_period_s")


def read_run(run: pathlib.Path) -> tuple[dict, list[dict]]:
    """(settings, rows of the run's own key) of one bench_manip output folder."""
    summary_path, log_path = run / "summary.json", run / "episodes.jsonl"
    if not summary_path.is_file() or not log_path.is_file():
        raise ValueError(f"{run}: not a bench_manip output (summary.json and episodes.jsonl expected)")
    settings = json.loads(summary_path.read_text())["settings"]
    rows = [json.loads(line) for line in log_path.read_text().splitlines() if line.strip()]
    return settings, [r for r in rows if r.get("run_key") == settings["run_key"]]


def pool(runs: list[pathlib.Path]) -> tuple[dict, list[dict], list[str]]:
    """(design settings, pooled rows, methods present in every run); ValueError when runs disagree.

    A run made with --only-tasks gives those tasks; a full run gives the tasks no such run gives.
    """
    read = [(run, *read_run(run)) for run in runs]
    design = {k: read[0][1].get(k) for k in DESIGN_KEYS}
    for run, settings, _ in read:
        this = {k: settings.get(k) for k in DESIGN_KEYS}
        if this != design:
            diff = sorted(k for k in DESIGN_KEYS if this[k] != design[k])
            raise ValueError(f"{run}: another design than {runs[0]} ({', '.join(diff)} differ)")
    source: dict[str, int] = {}  # task -> index into read
    for partial in (True, False):
        for i, (_, settings, _) in enumerate(read):
            if ("only_tasks" in settings) != partial:
                continue
            for task in settings.get("only_tasks", settings["tasks"]):
                if partial and task in source:
                    raise ValueError(f"task {task!r} is in both {read[source[task]][0]} and {read[i][0]}")
                source.setdefault(task, i)
    missing = [t for t in design["tasks"] if t not in source]
    if missing:
        raise ValueError(f"no run covers task(s) {', '.join(missing)}")
    methods = [m for m in read[0][1]["methods"] if all(m in settings["methods"] for _, settings, _ in read)]
    rows = [
        r for i, (_, _, mine) in enumerate(read) for r in mine if source.get(r["task"]) == i and r["method"] in methods
    ]
    pooled_from = {task: f"{read[i][0]} (run key {read[i][1]['run_key']})" for task, i in source.items()}
    return design | {"methods": methods, "pooled_from": pooled_from}, rows, methods


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", nargs="+", type=pathlib.Path, help="bench_manip output folders")
    parser.add_argument("--out", type=pathlib.Path, required=True)
    args = parser.parse_args(argv)
    try:
        settings, rows, methods = pool(args.runs)
    except (ValueError, KeyError, json.JSONDecodeError) as error:
        parser.error(str(error))
    args.out.mkdir(parents=True, exist_ok=True)
    summary = summarise(rows, methods, settings["tasks"], BINS, settings["episodes"])
    summary["settings"] = settings
    (args.out / "summary.json").write_text(json.dumps(json_safe(summary), indent=2, allow_nan=False) + "\n")
    write_plots(rows, summary, methods, BINS, args.out)
    write_report(summary, args.out)
    print(json.dumps(json_safe({m: round(v["success"], 3) for m, v in summary["methods"].items()})))
    print(f"[bench_manip_pool] wrote {args.out / 'summary.json'} and {args.out / 'report.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
