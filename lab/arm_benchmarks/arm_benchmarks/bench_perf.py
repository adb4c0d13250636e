"""bench_perf: speed figures of every stage, merged into results/perf/summary.json.

Each package contributes a `perf.measure() -> dict` (arm_sim's own is render_fps); packages that
are not installed are skipped and said so."""

import argparse
import faulthandler
import importlib
import json
import os
import pathlib
import time

from arm_benchmarks.machine import machine_description

PERF_MEASUREMENTS = (
    ("arm_benchmarks.perf_sim", "measure"),
    ("arm_benchmarks.perf_segmentation", "measure"),
    ("arm_benchmarks.perf_reconstruction", "measure"),
    ("arm_training.reconstruction.training.measure", "measure_training"),
    ("arm_benchmarks.perf_planner", "measure"),
    ("arm_benchmarks.perf_planner_graph", "measure"),  # the graph under load, minutes
)


def merge_summary(path: pathlib.Path, figures: dict) -> dict:
    summary = json.loads(path.read_text()) if path.exists() else {}
    summary.update(figures)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(summary, indent=2, sort_keys=True) + "\n")
    return summary


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="results/perf", help="output folder")
    parser.add_argument("--only", nargs="*", default=None, help="module names to run (default: all)")
    args = parser.parse_args(argv)
    faulthandler.enable()  # a crash in native code leaves the Python stacks of every thread
    out = pathlib.Path(args.out)
    figures = {
        "machine": machine_description(),
        "measured_at": time.strftime("%Y-%m-%dT%H:%M:%S"),
    }
    figures["cpu_count"] = os.cpu_count()
    for name, function in PERF_MEASUREMENTS:
        if args.only and name not in args.only and name.split(".")[0] not in args.only:
            continue
        try:
            module = importlib.import_module(name)
        except ImportError as error:
            print(f"[bench_perf] skipping {name}: {error}")
            continue
        print(f"[bench_perf] measuring {name} ...", flush=True)
        result = getattr(module, function)()
        figures.update(result)
        print(json.dumps({k: (round(v, 4) if isinstance(v, float) else v) for k, v in result.items()}), flush=True)
    summary = merge_summary(out / "summary.json", figures)
    print(f"[bench_perf] wrote {out / 'summary.json'} ({len(summary)} figures)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
