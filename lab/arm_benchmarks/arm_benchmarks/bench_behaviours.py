"""bench_behaviours: how often each physical behaviour the test suite asserts holds.

The suite asserts a physical outcome (a grasp lifts the lamp upright, a pushed cylinder arrives
standing, ...) with arm_core.repeated_runs.holds_repeatedly: in NEEDED of up to RUNS runs (2 of 6)
whose initial states differ by far less than a real robot's uncertainty (objects moved by up to 1e-5 m
and 1e-4 rad, MPPI seeded differently). This benchmark runs the same tests with every behaviour tried
--runs times (no early stop) and reports, per behaviour, the share of runs in which it held and the
chance that the suite's rule fails on a machine whose rounding draws other runs (from that share, runs independent).

    bench_behaviours [--runs 10] [--out results/behaviours] [-k EXPRESSION] [TEST_FILE ...]

Run from the repository root (the test files are read from the source tree). Writes summary.json and
report.md; each finished test is appended to runs.jsonl, so an interrupted run resumes.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import time
from math import comb

import numpy as np
import pytest

import arm_core.repeated_runs
from arm_benchmarks.machine import machine_description
from arm_benchmarks.stats import json_safe, wilson_interval

DEFAULT_TESTS = ("src/arm_planner/test/test_planner.py", "lab/arm_benchmarks/test/test_world_execution.py")


def suite_failure_chance(
    p_hold: float, runs: int = arm_core.repeated_runs.RUNS, needed: int = arm_core.repeated_runs.NEEDED
):
    """Chance that fewer than `needed` of `runs` independent runs hold, each holding with p_hold."""
    return sum(comb(runs, k) * p_hold**k * (1 - p_hold) ** (runs - k) for k in range(needed))


class BehaviourRecorder:
    """pytest plugin: replaces holds_repeatedly by one that makes every run and records the outcomes of
    each test (several behaviours in one test are numbered)."""

    def __init__(self, runs: int, log: pathlib.Path, done: set[str]):
        self.runs, self.log, self.done = runs, log, done
        self.outcomes: dict[str, list[bool]] = {}

    def _record(self, attempt, runs: int = arm_core.repeated_runs.RUNS, needed: int = arm_core.repeated_runs.NEEDED):
        test = os.environ.get("PYTEST_CURRENT_TEST", "?").rsplit(" ", 1)[0]
        name = test
        k = 1
        while name in self.outcomes:
            k += 1
            name = f"{test} #{k}"
        started = time.perf_counter()
        outcomes = [attempt(run) for run in range(self.runs)]
        held = [bool(ok) for ok, _ in outcomes]
        self.outcomes[name] = held
        row = {
            "behaviour": name,
            "held": held,
            "details": [repr(detail) for _, detail in outcomes],
            "seconds": round(time.perf_counter() - started, 1),
        }
        with self.log.open("a") as sink:
            sink.write(json.dumps(row) + "\n")
        return sum(held) >= needed * self.runs / runs, outcomes

    def pytest_configure(self, config):
        self._original = arm_core.repeated_runs.holds_repeatedly
        arm_core.repeated_runs.holds_repeatedly = self._record

    def pytest_unconfigure(self, config):
        arm_core.repeated_runs.holds_repeatedly = self._original

    def pytest_collection_modifyitems(self, config, items):
        items[:] = [item for item in items if item.nodeid not in self.done]


def summarise(rows: list[dict], runs: int) -> dict:
    behaviours = {}
    for row in rows:
        held = row["held"]
        rate = sum(held) / len(held)
        lo, hi = wilson_interval(sum(held), len(held))
        behaviours[row["behaviour"]] = {
            "runs": len(held),
            "held": sum(held),
            "hold_rate": rate,
            "hold_rate_ci90": [lo, hi],
            "suite_failure_chance": suite_failure_chance(rate),
            "seconds": row.get("seconds"),
        }
    passes = [1.0 - b["suite_failure_chance"] for b in behaviours.values()]
    return {"runs_per_behaviour": runs, "behaviours": behaviours, "any_failure_chance": 1.0 - float(np.prod(passes))}


def write_report(summary: dict, path: pathlib.Path) -> None:
    lines = [
        "# Physical behaviours the test suite asserts: how often each holds",
        "",
        f"Each behaviour tried {summary['runs_per_behaviour']} times (run 0 as written; run k: objects moved by "
        "up to 1e-5 m and turned by up to 1e-4 rad, MPPI seed k). The suite asserts "
        f"{arm_core.repeated_runs.NEEDED} of up to {arm_core.repeated_runs.RUNS} runs; 'suite fails' is the chance "
        "that it does not, from the measured rate.",
        "",
        f"Machine: {summary.get('machine', 'not recorded')}.",
        "",
        "| behaviour | held | rate (90 % interval) | suite fails |",
        "|---|---|---|---|",
    ]
    for name, b in summary["behaviours"].items():
        lo, hi = b["hold_rate_ci90"]
        lines.append(
            f"| `{name}` | {b['held']} / {b['runs']} | {b['hold_rate']:.2f} ({lo:.2f}-{hi:.2f}) | "
            f"{b['suite_failure_chance']:.3f} |"
        )
    lines += ["", f"Chance that at least one of them fails on a machine: {summary['any_failure_chance']:.3f}."]
    path.write_text("\n".join(lines) + "\n")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("tests", nargs="*", default=list(DEFAULT_TESTS), help="test files (from the repository root)")
    parser.add_argument("--runs", type=int, default=10, help="runs of each behaviour")
    parser.add_argument("--out", default="results/behaviours")
    parser.add_argument("-k", dest="keyword", default=None, help="only the tests pytest -k selects")
    parser.add_argument("--fresh", action="store_true", help="ignore earlier runs in --out")
    args = parser.parse_args(argv)
    missing = [t for t in args.tests if not pathlib.Path(t).is_file()]
    if missing:
        parser.error(f"no such test file {missing}: run from the repository root")
    if args.runs < 1:
        parser.error("--runs must be at least 1")
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    log = out / "runs.jsonl"
    if args.fresh and log.exists():
        log.unlink()
    rows = [json.loads(line) for line in log.read_text().splitlines()] if log.exists() else []
    rows = [r for r in rows if len(r["held"]) == args.runs]
    done = {r["behaviour"].split(" #")[0] for r in rows}
    recorder = BehaviourRecorder(args.runs, log, done)
    selection = ["-k", args.keyword] if args.keyword else []
    code = pytest.main(["-q", "-p", "no:cacheprovider", *selection, *args.tests], plugins=[recorder])
    rows = [json.loads(line) for line in log.read_text().splitlines()] if log.exists() else []
    rows = [r for r in rows if len(r["held"]) == args.runs]
    summary = summarise(rows, args.runs) | {"pytest_exit_code": int(code), "tests": args.tests}
    summary["machine"] = machine_description()
    (out / "summary.json").write_text(json.dumps(json_safe(summary), indent=2) + "\n")
    write_report(summary, out / "report.md")
    print(f"[bench_behaviours] wrote {out / 'summary.json'} and {out / 'report.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
