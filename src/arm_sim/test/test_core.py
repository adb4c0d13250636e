import numpy as np
import pytest

from arm_sim.core import COMMAND_NAMES, trajectory_targets


def test_trajectory_targets_interpolate_and_validate():
    current = np.zeros(8)
    targets = trajectory_targets(COMMAND_NAMES[:2], [0.5, 1.0], [[1.0, 2.0], [1.0, 2.0]], current, 0.1)
    assert targets.shape == (10, 8) and np.allclose(targets[4, :2], [1.0, 2.0])
    assert np.allclose(targets[1, :2], [0.4, 0.8])
    assert np.all(targets[:, 2:] == 0)
    for names, times, positions in [
        (["elbow"], [1.0], [[0.0]]),
        (COMMAND_NAMES[:1], [1.0, 0.5], [[0.0], [0.0]]),
        (COMMAND_NAMES[:1], [1.0], [[np.nan]]),
        (COMMAND_NAMES[:1], [], []),
    ]:
        with pytest.raises(ValueError):
            trajectory_targets(names, times, positions, current, 0.1)
