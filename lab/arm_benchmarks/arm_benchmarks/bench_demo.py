"""bench_demo: the main job (`demo`) over several scenes, to count how often the robot does its task.

    bench_demo [--seeds 1-10] [--task grasp] [--objects 8] [--out results/demo_bench]

Each seed runs the whole node graph once (`demo --seed S`, realistic domain) into OUT/seed_<S>/; a
seed whose summary.json exists is not run again (resume). Writes OUT/summary.json and OUT/report.md:
per seed the attempts, the last target chosen and why, met in the twin, done in the simulator, or why
no goal was sent; the count done, and done at the first attempt.
"""

import argparse
import json
import pathlib
import subprocess
import sys
import time

from tqdm import tqdm

from arm_benchmarks.machine import machine_description
from arm_benchmarks.stats import wilson_interval
from arm_core.atomic_io import atomic_write_json, atomic_write_text


def parse_seeds(text: str) -> list[int]:
    """'1-10' or '1,4,7' -> seeds."""
    seeds = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        seeds += list(range(int(lo), int(hi or lo) + 1))
    return seeds


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=parse_seeds, default=parse_seeds("1-10"))
    parser.add_argument("--task", choices=["grasp", "push", "rearrange"], default="grasp")
    parser.add_argument("--objects", type=int, default=8)
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("results/demo_bench"))
    parser.add_argument("--timeout-s", type=float, default=900.0, help="longest run of one seed")
    return parser.parse_args(argv)


def run_seed(seed: int, args) -> dict:
    folder = args.out / f"seed_{seed}"
    if (folder / "summary.json").is_file():
        return json.loads((folder / "summary.json").read_text())
    command = ["demo", "--seed", str(seed), "--task", args.task, "--objects", str(args.objects), "--out", str(folder)]
    started = time.monotonic()
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=args.timeout_s)
        log, code = done.stdout + done.stderr, done.returncode
    except subprocess.TimeoutExpired as error:
        log, code = f"{error.stdout or ''}{error.stderr or ''}", "timeout"
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "demo.log").write_text(log if isinstance(log, str) else str(log))
    if (folder / "summary.json").is_file():
        return json.loads((folder / "summary.json").read_text())
    return {"seed": seed, "error": f"demo exited {code} after {time.monotonic() - started:.0f} s without a summary"}


def outcome(summary: dict) -> str:
    task = summary.get("task") or {}
    if "error" in summary or "error" in task:
        return "error"
    if task.get("target_id") is None:
        return "no target"
    return "done" if task.get("success_in_sim") else "not done"


def main(argv=None) -> int:
    args = parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for seed in tqdm(args.seeds, desc="demo seeds", unit="run", file=sys.stderr):
        summary = run_seed(seed, args)
        task = summary.get("task") or {}
        rows.append({
            "seed": seed,
            "outcome": outcome(summary),
            "instances": summary.get("segmented_instances"),
            "target_id": task.get("target_id"),
            "why": task.get("why") or task.get("error") or summary.get("error"),
            "planned_success": task.get("planned_success"),
            "attempts": len(task.get("attempts") or []),
            "done_at_first_attempt": bool(task.get("done_at_first_attempt")),
            "target_displacement_m": task.get("target_displacement_m"),
            "wall_s": summary.get("wall_s"),
        })  # fmt: skip
    done = sum(r["outcome"] == "done" for r in rows)
    total = {
        "task": args.task,
        "objects": args.objects,
        "seeds": args.seeds,
        "done": done,
        "done_at_first_attempt": sum(r["done_at_first_attempt"] for r in rows),
        "runs": len(rows),
        "done_interval_90": list(wilson_interval(done, len(rows))),
        "no_target": sum(r["outcome"] == "no target" for r in rows),
        "errors": sum(r["outcome"] == "error" for r in rows),
        "machine": machine_description(),
        "rows": rows,
    }
    atomic_write_json(args.out / "summary.json", total, indent=1)
    lines = [
        f"# bench_demo: `demo --task {args.task}` over {len(rows)} scenes ({args.objects} objects)",
        "",
        f"Done in the simulator: {done} of {len(rows)} (90 % interval {total['done_interval_90'][0]:.2f}-"
        f"{total['done_interval_90'][1]:.2f}); at the first attempt: {total['done_at_first_attempt']}; "
        f"no suitable target: {total['no_target']}; errors: {total['errors']}. Machine: {total['machine']}.",
        "",
        "| seed | outcome | attempts | instances | target | met in the twin | target moved (m) | why |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['seed']} | {r['outcome']} | {r['attempts']} | {r['instances']} | {r['target_id']} | "
            f"{r['planned_success']} | {r['target_displacement_m']} | {r['why']} |"
        )
    atomic_write_text(args.out / "report.md", "\n".join(lines) + "\n")
    print(f"{done}/{len(rows)} done -> {args.out / 'summary.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
