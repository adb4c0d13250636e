"""Helpers for integration tests: real node processes (arm_ros.processes) over DDS on an isolated domain."""

import pathlib
import time

import pytest
import rclpy

from arm_benchmarks.robustness.nodes import reconstruction_checkpoint, reconstruction_params
from arm_ros.processes import NodeProcess, executable, node_built


def require_built(*keys: str) -> None:
    """Fail (not skip) when a node the test needs is not installed: `make test` builds them all."""
    missing = [f"{key} ({executable(key)})" for key in keys if not node_built(key)]
    if missing:
        pytest.fail(f"node executable(s) not built: {', '.join(missing)}; run `make setup` (colcon build)")


def start_node(key: str, log_dir, **kwargs) -> NodeProcess:
    """Start the node of key (arm_ros.processes.NODES) with its installed parameter file, log in
    log_dir/<key>.log; kwargs go to NodeProcess (params, remaps, args, ...)."""
    require_built(key)
    return NodeProcess(key, pathlib.Path(log_dir) / f"{key}.log", **kwargs)


def spin_until(node, predicate, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
        if predicate():
            return True
    return predicate()


def require_reconstruction_params() -> dict:
    """Parameters of the reconstruction node in robustness runs (its checkpoint); fails without one."""
    params = reconstruction_params()
    if params is None:
        pytest.fail(f"no reconstruction checkpoint ({reconstruction_checkpoint()}); it ships in the repository")
    return params
