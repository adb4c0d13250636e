"""Starting node processes for the robustness suite.

The reconstruction node runs with the shipped checkpoint (ARM_ROBUSTNESS_CHECKPOINT overrides it,
ARM_ROBUSTNESS_RECON_PARAMS="name:=value ..." adds parameters); tests that need it skip without one.
"""

import os

import pytest

from arm_sim.robustness import NodeProcess, node_built, reconstruction_checkpoint


def reconstruction_params() -> dict:
    checkpoint = reconstruction_checkpoint()
    if checkpoint is None:
        pytest.skip("no reconstruction checkpoint yet (src/arm_reconstruction/arm_reconstruction/checkpoints/arm.pt)")
    params = {"checkpoint_path": str(checkpoint)}
    for item in os.environ.get("ARM_ROBUSTNESS_RECON_PARAMS", "").split():
        name, value = item.split(":=")
        params[name] = float(value) if value.replace(".", "", 1).isdigit() else value
    return params


def start(key: str, log_dir, **kwargs) -> NodeProcess:
    if not node_built(key):
        pytest.skip(f"{key} node is not built (colcon build)")
    return NodeProcess(key, log_dir / f"{key}.log", **kwargs)
