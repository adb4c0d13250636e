"""Starting node processes for the robustness suite.

The reconstruction node runs with the shipped checkpoint (ARM_ROBUSTNESS_CHECKPOINT overrides it,
ARM_ROBUSTNESS_RECON_PARAMS="name:=value ..." adds parameters); tests that need it skip without one.
"""

import pytest

from arm_benchmarks import robustness
from arm_benchmarks.robustness import NodeProcess, Probe, convention_report, node_built


def reconstruction_params() -> dict:
    params = robustness.reconstruction_params()
    if params is None:
        pytest.skip("no reconstruction checkpoint yet (src/arm_reconstruction/arm_reconstruction/checkpoints/arm.pt)")
    return params


def start(key: str, log_dir, **kwargs) -> NodeProcess:
    if not node_built(key):
        pytest.skip(f"{key} node is not built (colcon build)")
    return NodeProcess(key, log_dir / f"{key}.log", **kwargs)


def run_against(key: str, log_dir, cases, endpoints: dict | None = None, **start_kwargs) -> dict:
    """Start the node, run cases(probe, process) -> report from a DDS probe, then read each of
    `endpoints` (name -> fn(probe)) and the node's conventions, and stop it with SIGINT.
    -> {"report", "conventions", "exit_code", "log", **endpoints}."""
    process = start(key, log_dir, **start_kwargs)
    probe = Probe()
    try:
        report = cases(probe, process)
        seen = {name: read(probe) for name, read in (endpoints or {}).items()}
        conventions = convention_report(probe, key)
    finally:
        probe.close()
        exit_code = process.stop()
    return {"report": report, "conventions": conventions, "exit_code": exit_code, "log": process.log(), **seen}
