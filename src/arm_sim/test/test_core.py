import numpy as np
import pytest

from arm_sim.core import COMMAND_NAMES, SimSession, trajectory_targets
from arm_sim.world import SERVO_PERIOD_S


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


def test_the_sim_session_follows_a_trajectory_as_the_world_executes_it():
    """sim_node's controller (SimSession.follow, then steps of one physics tick) and SimWorld.execute
    (the benchmarks' executor, the twin's control ramp) drive the servos alike: the same state at the end."""
    node_side, world_side = SimSession(seed=3, n_objects=3), SimSession(seed=3, n_objects=3)
    start = node_side.command()
    times = np.array([0.3, 0.6])
    positions = np.vstack([start + 0.2, start - 0.1])
    positions[:, 7] = start[7]
    assert node_side.follow(COMMAND_NAMES, times, positions) == round(0.6 / SERVO_PERIOD_S)
    while node_side.following:
        node_side.step(0.02)
    world_side.world.execute(times, positions)
    np.testing.assert_array_equal(node_side.world.data.qpos, world_side.world.data.qpos)
    with pytest.raises(ValueError):
        node_side.follow(COMMAND_NAMES[:1], [0.5, 0.2], [[0.0], [0.0]])
    node_side.step(0.02)
    np.testing.assert_allclose(node_side.command(), positions[-1])
    node_side.close()
    world_side.close()


def test_trajectory_targets_keep_to_the_trajectorys_start():
    current = np.zeros(8)
    late = trajectory_targets(COMMAND_NAMES[:1], [0.2, 0.4], [[1.0], [2.0]], current, 0.1, started_s_ago=0.1)
    np.testing.assert_allclose(late[:, 0], [1.0, 1.5, 2.0])  # from now to the point at 0.2 s, then on
    past = trajectory_targets(COMMAND_NAMES[:1], [0.2, 0.4], [[1.0], [2.0]], current, 0.1, started_s_ago=1.0)
    np.testing.assert_allclose(past[:, 0], [2.0])  # all of it past: the last point
    early = trajectory_targets(COMMAND_NAMES[:1], [0.2], [[1.0]], current, 0.1, started_s_ago=-0.1)
    np.testing.assert_allclose(early[:, 0], [0.0, 0.5, 1.0])  # held until it starts


def test_a_streamed_part_that_arrives_late_continues_the_plan():
    """A plan sent in two parts with one time base (the second arriving two servo periods after its
    stamp) ends where the whole plan sent at once does; without the stamp it would lag behind."""
    whole, streamed = SimSession(seed=3, n_objects=3), SimSession(seed=3, n_objects=3)
    start = whole.command()
    times = 0.02 * np.arange(1, 31)
    positions = start + np.linspace(0.0, 0.3, 30)[:, None] * np.r_[np.ones(7), 0.0]
    whole.follow(COMMAND_NAMES, times, positions, start_s=whole.time_s)
    streamed.follow(COMMAND_NAMES, times[:10], positions[:10], start_s=streamed.time_s)
    for session in (whole, streamed):
        session.step(0.16)
    stamp_s = streamed.time_s  # the second part: the points after 0.16 s, stamped now, received 0.02 s later
    streamed.step(0.02)
    streamed.follow(COMMAND_NAMES, times[8:] - 0.16, positions[8:], start_s=stamp_s)
    for session in (whole, streamed):
        session.step(0.02)
        while session.following:
            session.step(0.02)
    assert streamed.time_s == pytest.approx(whole.time_s)
    np.testing.assert_allclose(streamed.command(), whole.command())
    np.testing.assert_allclose(streamed.world.data.qpos[:7], whole.world.data.qpos[:7], atol=1e-9)
    whole.close()
    streamed.close()
