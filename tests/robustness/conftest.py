"""Shared fixtures of the robustness suite: rendered input frames, a DDS probe, node processes.

Node processes are started with robustness_nodes.start (see there for the reconstruction checkpoint).
"""

import pytest

from arm_sim.robustness import Probe, render_frames


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


@pytest.fixture
def probe():
    p = Probe()
    yield p
    p.close()
