"""A case (input builder and expectation) and the report every runner returns."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from arm_benchmarks.robustness.logs import error_lines, rate_limit_violations, tracebacks


@dataclasses.dataclass
class Case:
    name: str
    expect: str  # "reject" | "valid" | "silent"
    build: Callable  # stamp_s -> {topic: message}
    reason: str = ""  # text the node's error log should contain for it


def finish_report(node: str, process, results: list[dict], invalid_outputs: list[str], extra: dict) -> dict:
    log = process.log()
    lines = error_lines(log)
    causes: dict[str, int] = {}
    for line in lines:
        causes[line.cause] = causes.get(line.cause, 0) + 1
    missing = [r["name"] for r in results if r.get("reason") and r["reason"].lower() not in log.lower()]
    return {
        "node": node,
        "inputs_tried": len(results),
        "cases": results,
        "cases_failed": [r["name"] for r in results if not r["ok"]],
        "alive": process.alive(),
        "error_lines": len(lines),
        "error_lines_by_cause": causes,
        "rate_limit_violations": rate_limit_violations(lines),
        "reasons_not_logged": missing,
        "tracebacks": tracebacks(log),
        "invalid_outputs": invalid_outputs,
        **extra,
    }


def judge(expect: str, published: bool, rejected: bool) -> tuple[bool, str]:
    outcome = "published" if published else ("rejected" if rejected else "nothing")
    if expect == "reject":
        return not published, outcome
    if expect == "silent":
        return not published, outcome
    return True, outcome


def case_result(case: Case, published: bool, rejected: bool, reason: str, **measured) -> dict:
    """The report row of one case: judged by its expectation, except that a "valid frame" case is
    passed only when its output was published; `reason` is reported (empty when it does not apply)."""
    ok, outcome = judge(case.expect, published, rejected)
    if case.name.startswith("valid frame"):
        ok = published
    return {"name": case.name, "expect": case.expect, "outcome": outcome, "ok": ok, **measured, "reason": reason}


def sprinkle_invalid_depth(depth):
    """10 % NaN, 5 % inf and 5 % negative pixels, seeded."""
    rng = np.random.default_rng(0)
    mask = rng.random(depth.shape)
    depth[mask < 0.1] = np.nan
    depth[(mask >= 0.1) & (mask < 0.15)] = np.inf
    depth[(mask >= 0.15) & (mask < 0.2)] = -1.0
    return depth
