"""Shared fixtures of the robustness suite: rendered input frames and a log directory.

Node processes are started with ros_helpers.start_node (robustness_nodes.run_against); the
reconstruction checkpoint comes from ros_helpers.require_reconstruction_params.
"""

import pathlib
import shutil
import tempfile

import pytest

from arm_benchmarks.robustness.frames import render_frames


@pytest.fixture(scope="session")
def frames():
    """A 6-object scene, an empty table and a 40-object scene, 320x240, one camera."""
    return {
        "normal": render_frames(6, seed=1)[0],
        "empty": render_frames(0, seed=1)[0],
        "crowded": render_frames(40, seed=2, settle_s=0.8)[0],
    }


@pytest.fixture(scope="session")
def robustness_logs():
    """Node logs and bags of the session, outside pytest's shared basetemp (other pytest sessions on
    the machine prune that while long node runs still write to it)."""
    path = pathlib.Path(tempfile.mkdtemp(prefix="arm_robustness_"))
    yield path
    shutil.rmtree(path, ignore_errors=True)
