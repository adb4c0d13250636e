"""Scene history by stamp, and following a target into newer meshes by position."""

import numpy as np
import pytest

from arm_planner.scenes import Scene, SceneHistory, follow_target, observed_displacement
from arm_planner.twin import TwinObject


def _scene(stamp_ns, centres_by_id):
    objects = []
    for object_id, centre in centres_by_id.items():
        T = np.eye(4)
        T[:3, 3] = centre
        objects.append(TwinObject(id=object_id, T_world_object=T, mesh=None, convex_parts=[]))
    return Scene(objects, 0.0, stamp_ns)


def test_history_is_bounded_and_found_by_stamp():
    history = SceneHistory(capacity=2)
    assert history.latest() is None and history.stamped(0) is None
    for stamp in (10, 20, 30):
        history.add(_scene(stamp, {1: (0, 0, 0)}))
    assert len(history) == 2 and history.stamps_ns() == [20, 30]
    assert history.stamped(0).stamp_ns == 30
    assert history.stamped(20).stamp_ns == 20
    assert history.stamped(10) is None  # pushed out
    with pytest.raises(ValueError):
        SceneHistory(capacity=0)


def test_follow_target_by_nearest_centre_within_radius():
    old = _scene(1, {3: (0.1, 0.0, 0.05), 5: (0.3, 0.0, 0.05)})
    newer = _scene(2, {1: (0.31, 0.0, 0.05), 2: (0.12, 0.01, 0.06)})  # relabelled, the target moved 2.4 cm
    assert follow_target(old, 3, newer, 0.05) == 2
    assert follow_target(old, 5, newer, 0.05) == 1
    assert follow_target(old, 3, newer, 0.01) is None
    assert follow_target(old, 9, newer, 0.05) is None  # not in the old scene
    assert follow_target(old, 3, _scene(3, {}), 0.05) is None


def test_observed_displacement_finds_the_target_where_it_was_or_where_the_task_put_it():
    before = _scene(1, {3: (0.1, 0.0, 0.05), 5: (0.3, 0.0, 0.05)})
    pushed = _scene(2, {1: (0.3, 0.0, 0.05), 2: (0.1, 0.2, 0.05)})
    assert np.allclose(observed_displacement(before, 3, pushed, (0.0, 0.21, 0.0), 0.05), (0.0, 0.2, 0.0))
    missed = _scene(3, {1: (0.3, 0.0, 0.05), 2: (0.11, 0.0, 0.05)})  # the push left it where it was
    assert np.allclose(observed_displacement(before, 3, missed, (0.0, 0.21, 0.0), 0.05), (0.01, 0.0, 0.0))
    assert observed_displacement(before, 3, _scene(4, {1: (0.3, 0.0, 0.05)}), (0.0, 0.21, 0.0), 0.05) is None
    assert observed_displacement(before, 9, pushed, (0.0, 0.0, 0.0), 0.05) is None


def test_a_neighbour_that_did_not_move_is_not_taken_for_the_target():
    before = _scene(1, {3: (0.1, 0.0, 0.05), 5: (0.16, 0.0, 0.05)})
    lifted_out_of_view = _scene(2, {1: (0.16, 0.0, 0.05)})  # only the neighbour is seen
    assert observed_displacement(before, 3, lifted_out_of_view, (0.0, 0.0, 0.1), 0.15) is None
    lifted = _scene(3, {1: (0.16, 0.0, 0.05), 2: (0.1, 0.0, 0.15)})
    assert np.allclose(observed_displacement(before, 3, lifted, (0.0, 0.0, 0.1), 0.15), (0.0, 0.0, 0.1))
