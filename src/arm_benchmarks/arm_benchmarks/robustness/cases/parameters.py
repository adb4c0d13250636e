"""Invalid parameters at start-up: malformed and extreme inputs and what the node must do with them."""

from __future__ import annotations

from arm_benchmarks.robustness.logs import tracebacks
from arm_ros.processes import NodeProcess, node_built

PARAMETER_CASES = [
    ("segmentation", "sync_queue_size", 0, "range"),
    ("segmentation", "image_reliability", "sometimes", "choice"),
    ("reconstruction", "k", 100.0, "range"),
    ("reconstruction", "method", "magic", "choice"),
    ("planner", "num_paths", 1, "range"),
    ("planner", "steps", "many", "type"),
    ("sim", "n_objects", 99, "range"),
    ("sim", "split", "test", "choice"),
]


def run_parameter_validation(log_dir, timeout_s: float = 60.0) -> list[dict]:
    """Start every node with one invalid parameter (all at once); each must exit with code 2, name the
    parameter and print no traceback."""
    started = []
    for i, (key, name, value, _) in enumerate(PARAMETER_CASES):
        if node_built(key):
            process = NodeProcess(key, log_dir / f"params_{i}" / f"{key}.log", params={name: value})
            started.append((i, process))
    results = []
    for i, process in started:
        key, name, value, kind = PARAMETER_CASES[i]
        code = process.wait(timeout_s)
        if code is None:
            process.stop()
        log = process.log()
        results.append(
            {
                "node": key,
                "parameter": name,
                "value": value,
                "kind": kind,
                "exit_code": code,
                "names_parameter": name in log,
                "tracebacks": tracebacks(log),
                "ok": code == 2 and name in log and not tracebacks(log),
            }
        )
    return results
