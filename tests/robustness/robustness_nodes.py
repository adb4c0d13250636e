"""Starting node processes for the robustness suite.

The reconstruction node runs with the shipped checkpoint (ARM_ROBUSTNESS_CHECKPOINT overrides it,
ARM_ROBUSTNESS_RECON_PARAMS="name:=value ..." adds parameters); tests that need it skip without one.
"""

import pytest

from arm_sim import robustness
from arm_sim.robustness import NodeProcess, node_built


def reconstruction_params() -> dict:
    params = robustness.reconstruction_params()
    if params is None:
        pytest.skip("no reconstruction checkpoint yet (src/arm_reconstruction/arm_reconstruction/checkpoints/arm.pt)")
    return params


def start(key: str, log_dir, **kwargs) -> NodeProcess:
    if not node_built(key):
        pytest.skip(f"{key} node is not built (colcon build)")
    return NodeProcess(key, log_dir / f"{key}.log", **kwargs)
