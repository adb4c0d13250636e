"""Shared fixtures of the robustness suite: rendered input frames, a DDS probe, node processes.

The reconstruction node runs with the shipped checkpoint (ARM_ROBUSTNESS_CHECKPOINT overrides it,
ARM_ROBUSTNESS_RECON_PARAMS="name:=value ..." adds parameters); tests that need it skip without one.
"""

import os

import pytest

from arm_sim.robustness import NodeProcess, Probe, node_built, reconstruction_checkpoint, render_frames


@pytest.fixture(scope="session")
def frames():
    """A 6-object scene, an empty table and a 40-object scene, 320x240, one camera."""
    return {
        "normal": render_frames(6, seed=1)[0],
        "empty": render_frames(0, seed=1)[0],
        "crowded": render_frames(40, seed=2, settle_s=0.8)[0],
    }


@pytest.fixture(scope="session")
def robustness_logs(tmp_path_factory):
    return tmp_path_factory.mktemp("robustness_logs")


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


@pytest.fixture
def probe():
    p = Probe()
    yield p
    p.close()
