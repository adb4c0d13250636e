"""Test stand-ins for the tasks' kinematics."""

import numpy as np


def poses_from(first: int):
    """Kinematics stand-in: position = qpos[..., first:first + 3], rotation = hand pointing down."""
    down = np.diag([1.0, -1.0, -1.0])
    return lambda qpos: (qpos[..., first : first + 3], np.broadcast_to(down, qpos.shape[:-1] + (3, 3)))
