"""Starting node processes for the robustness suite.

The reconstruction node runs with the shipped checkpoint (ARM_ROBUSTNESS_CHECKPOINT overrides it,
ARM_ROBUSTNESS_RECON_PARAMS="name:=value ..." adds parameters); tests that need it fail without one
(the shipped checkpoint is part of the repository).
"""

from arm_benchmarks.robustness.parameters import convention_report
from arm_benchmarks.robustness.probe import Probe

from ros_helpers import start_node


def run_against(key: str, log_dir, cases, endpoints: dict | None = None, **start_kwargs) -> dict:
    """Start the node, run cases(probe, process) -> report from a DDS probe, then read each of
    `endpoints` (name -> fn(probe)) and the node's conventions, and stop it with SIGINT.
    -> {"report", "conventions", "exit_code", "log", **endpoints}."""
    process = start_node(key, log_dir, **start_kwargs)
    probe = Probe()
    try:
        report = cases(probe, process)
        seen = {name: read(probe) for name, read in (endpoints or {}).items()}
        conventions = convention_report(probe, key)
    finally:
        probe.close()
        exit_code = process.stop()
    return {"report": report, "conventions": conventions, "exit_code": exit_code, "log": process.log(), **seen}
