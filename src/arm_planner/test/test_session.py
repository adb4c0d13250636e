import numpy as np
import pytest
import trimesh

from arm_planner.mppi import MppiConfig
from arm_planner.planner import PlannerConfig
from arm_planner.session import ManipulationSession
from arm_planner.twin import TwinObject
from arm_sim import robot


def _objects():
    box = trimesh.creation.box(extents=(0.05, 0.05, 0.08))
    T = np.eye(4)
    T[:3, 3] = (0.0, 0.0, 0.04)
    flat = trimesh.Trimesh(np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0.0]]), [[0, 1, 2]])
    far = np.eye(4)
    far[:3, 3] = (0.6, 0.0, 0.04)
    return [TwinObject(1, T, box, [box]), TwinObject(2, T, flat, []), TwinObject(3, far, box, [box])]


@pytest.fixture(scope="module")
def session():
    config = PlannerConfig(mppi=MppiConfig(steps=5, nthread=1), push_steps=0, rearrange_steps=0, realtime_factor=0.0)
    config.settle_s = 0.0
    s = ManipulationSession(config, 0.01)
    s.set_objects(_objects(), 0.0)
    yield s
    s.close()


def _ask(session, task="grasp", target=1, displacement=(0, 0, 0), q=robot.HOME_Q, opening=0.04):
    return session.request(task, target, displacement, 0.0, q, opening)


@pytest.mark.parametrize(
    "kwargs,reason",
    [
        (dict(task="juggle"), "unknown task"),
        (dict(target=9), "unknown target id 9"),
        (dict(target=2), "cannot be simulated"),
        (dict(target=3), "target out of reach"),
        (dict(task="push", displacement=(1.0, 0.0, 0.0)), "goal out of reach"),
        (dict(task="push", displacement=(np.nan, 0.0, 0.0)), "not 3 finite"),
        (dict(q=np.full(7, np.nan)), "finite angles"),
        (dict(opening=np.inf), "gripper opening"),
    ],
)
def test_bad_requests_are_refused_with_a_reason(session, kwargs, reason):
    outcome = _ask(session, **kwargs)
    assert not outcome.planned and not outcome.success
    assert reason in outcome.message
    assert outcome.infeasible == ("out of reach" in reason)


def test_no_objects_yet_is_refused():
    outcome = ManipulationSession().request("grasp", 1, (0, 0, 0), 0.0, robot.HOME_Q, 0.04)
    assert "no reconstructed objects" in outcome.message


def test_valid_request_plans_a_trajectory_and_reuses_the_twin(session):
    outcome = _ask(session, task="push", displacement=(0.05, -0.3, 0.0))
    assert outcome.planned
    assert outcome.result.joint_positions.shape == (5, 8)
    assert outcome.joint_names[-1] == robot.FINGER_JOINT_NAMES[0]
    builds = session.twin_builds
    moved = _objects()
    moved[0].T_world_object[0, 3] = 0.02
    session.set_objects(moved, 0.0)
    assert _ask(session).planned
    assert session.twin_builds == builds


def test_push_cages_an_object_that_fits_between_the_fingers_unless_switched_off(session):
    assert _ask(session, task="push", displacement=(0.05, -0.3, 0.0)).planned
    assert type(session.planner._last_reward).__name__ == "CagePushReward"
    session.config.push_cage = False
    try:
        assert _ask(session, task="push", displacement=(0.05, -0.3, 0.0)).planned
        assert type(session.planner._last_reward).__name__ == "PushReward"
    finally:
        session.config.push_cage = True


def test_a_grasp_the_gripper_cannot_hold_is_refused_as_infeasible_and_a_rearrange_pushes_it():
    wide = trimesh.creation.box(extents=(0.16, 0.15, 0.06))
    T = np.eye(4)
    T[:3, 3] = (0.0, 0.0, 0.03)
    config = PlannerConfig(mppi=MppiConfig(steps=5, nthread=1), push_steps=0, rearrange_steps=0, realtime_factor=0.0)
    config.settle_s = 0.0
    s = ManipulationSession(config, 0.01)
    try:
        s.set_objects([TwinObject(1, T, wide, [wide])], 0.0)
        grasp = _ask(s, target=1)
        assert not grasp.planned and grasp.infeasible
        assert "cannot pick it up" in grasp.message and "15.0 cm" in grasp.message
        rearrange = _ask(s, task="rearrange", target=1, displacement=(0.0, 0.1, 0.0))
        assert rearrange.planned and not rearrange.infeasible
        assert type(s.planner._last_reward).__name__ == "PushReward"
    finally:
        s.close()


@pytest.mark.parametrize("tilt_deg", [24.0, 25.0, 26.0])
def test_a_target_that_falls_over_in_the_twin_is_refused_with_the_reason(tilt_deg):
    """The camera saw each object at rest: a reconstruction that topples while the twin settles (a
    16 cm bar leaning 24-26 degrees on one edge) gets no plan, while one that stands is planned."""
    bar = trimesh.creation.box(extents=(0.02, 0.02, 0.16))
    leaning = np.eye(4)
    leaning[:3, :3] = trimesh.transformations.rotation_matrix(np.radians(tilt_deg), (1, 0, 0))[:3, :3]
    leaning[:3, 3] = (0.1, -0.1, -bar.copy().apply_transform(leaning).bounds[0, 2])
    standing = np.eye(4)
    standing[:3, 3] = (0.1, 0.1, 0.08)
    config = PlannerConfig(mppi=MppiConfig(steps=2, nthread=1), realtime_factor=0.0)
    s = ManipulationSession(config, 0.01)
    try:
        s.set_objects([TwinObject(1, leaning, bar, [bar]), TwinObject(2, standing, bar, [bar])], 0.0)
        fallen = _ask(s, target=1)
        assert not fallen.planned and not fallen.success
        assert "does not rest where the camera saw it" in fallen.message
        assert _ask(s, target=2).planned
    finally:
        s.close()
