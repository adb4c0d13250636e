"""Invalid parameters at start-up: malformed and extreme inputs and what the node must do with them."""

from __future__ import annotations

import time

from arm_benchmarks.robustness.logs import tracebacks
from arm_ros.processes import NODES, NodeProcess, node_built

PARAMETER_CASES = [
    ("segmentation", "sync_tolerance_s", 5.0, "range"),
    ("segmentation", "image_reliability", "sometimes", "choice"),
    ("reconstruction", "threshold", 1.5, "range"),
    ("reconstruction", "method", "magic", "choice"),
    ("planner", "num_paths", 1, "range"),
    ("planner", "steps", "many", "type"),
    ("planner", "execution", "sometimes", "choice"),
    ("sim", "n_objects", 99, "range"),
    ("sim", "visual_domain", "cartoon", "choice"),
]


def run_parameter_validation(log_dir, timeout_s: float = 120.0) -> list[dict]:
    """Start every node with one invalid parameter (all at once); each must exit with code 2 within
    timeout_s of its start, name itself and the parameter, and print no traceback. A node still
    running then has its threads' stacks written to its log (SIGABRT + faulthandler) before it is
    stopped."""
    started = []
    for i, (key, name, value, _) in enumerate(PARAMETER_CASES):
        if node_built(key):
            log = log_dir / f"params_{i}" / f"{key}.log"
            process = NodeProcess(key, log, params={name: value}, env={"PYTHONFAULTHANDLER": "1"})
            started.append((i, process))
    results = []
    for i, process in started:
        key, name, value, kind = PARAMETER_CASES[i]
        code = process.wait(max(0.0, process.started_s + timeout_s - time.monotonic()))
        if code is None:
            process.dump_stacks_and_stop()
        log = process.log()
        names_node = f"[{NODES[key][1]}] invalid configuration" in log
        ok = code == 2 and name in log and names_node and not tracebacks(log)
        results.append(
            {
                "node": key,
                "parameter": name,
                "value": value,
                "kind": kind,
                "exit_code": code,
                "names_parameter": name in log,
                "names_node": names_node,
                "tracebacks": tracebacks(log),
                "ok": ok,
                "log_tail": "" if ok else log[-2000:],
            }
        )
    return results
