"""sim_node's ros2_control stand-ins over the real action interfaces: FollowJointTrajectory for the arm,
GripperCommand for the gripper (the sim stepped by a timer, as sim_node does)."""

import threading

import numpy as np
import pytest
import rclpy
from control_msgs.action import FollowJointTrajectory, GripperCommand
from control_msgs.msg import JointTolerance
from rclpy.action import ActionClient
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from arm_ros.conversions.stamps import seconds_to_duration
from arm_ros.executors import result_within
from arm_sim import robot
from arm_sim.controllers import SimControllers
from arm_sim.core import SimSession

TICK_S = 0.02


@pytest.fixture(scope="module")
def sim():
    rclpy.init()
    session = SimSession(seed=0, n_objects=3, width=64, height=48, depth_noise=False)
    host = Node("sim_controllers_test")
    lock = threading.Lock()
    controllers = SimControllers(
        host, session, "arm_controller", "gripper_controller", lambda: session.time_s, lambda frame: Header()
    )

    def tick():
        with lock:
            session.step(TICK_S)
            controllers.tick()

    host.create_timer(TICK_S / 4, tick)  # faster than real time
    client = Node("sim_controllers_client")
    arm = ActionClient(client, FollowJointTrajectory, "arm_controller/follow_joint_trajectory")
    gripper = ActionClient(client, GripperCommand, "gripper_controller/gripper_cmd")
    executor = MultiThreadedExecutor(num_threads=3)
    executor.add_node(host)
    executor.add_node(client)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    assert arm.wait_for_server(timeout_sec=10) and gripper.wait_for_server(timeout_sec=10)
    yield session, controllers, arm, gripper
    controllers.close()
    executor.shutdown()
    thread.join(timeout=10.0)
    host.destroy_node()
    client.destroy_node()
    rclpy.try_shutdown()


def _wait(future, timeout=30.0):
    return result_within(future, timeout)


def _arm_goal(session, offset_rad, duration_s=0.5, names=robot.JOINT_NAMES):
    start = session.world.joint_positions()[:7]
    target = start + offset_rad
    times = np.linspace(duration_s / 5, duration_s, 5)
    positions = start + np.outer(times / duration_s, target - start)
    points = [
        JointTrajectoryPoint(positions=q[: len(names)].tolist(), time_from_start=seconds_to_duration(float(t)))
        for t, q in zip(times, positions, strict=True)
    ]
    goal = FollowJointTrajectory.Goal(trajectory=JointTrajectory(joint_names=list(names), points=points))
    return goal, target


def test_a_trajectory_goal_is_followed_to_its_end_and_succeeds(sim):
    session, controllers, arm, _ = sim
    goal, target = _arm_goal(session, np.array([0.2, -0.1, 0.0, 0.1, 0.0, 0.1, 0.0]))
    goal.goal_tolerance = [JointTolerance(name=n, position=0.05) for n in robot.JOINT_NAMES]
    feedback = []
    handle = _wait(arm.send_goal_async(goal, feedback_callback=feedback.append))
    assert handle.accepted
    result = _wait(handle.get_result_async()).result
    assert result.error_code == FollowJointTrajectory.Result.SUCCESSFUL, result.error_string
    assert np.allclose(session.world.joint_positions()[:7], target, atol=0.05)
    assert feedback and list(feedback[-1].feedback.joint_names) == list(robot.JOINT_NAMES)


def test_a_goal_without_every_arm_joint_is_rejected(sim):
    session, _, arm, _ = sim
    goal, _ = _arm_goal(session, np.zeros(7), names=robot.JOINT_NAMES[:3])
    assert not _wait(arm.send_goal_async(goal)).accepted


def test_an_unreachable_goal_tolerance_aborts_the_goal(sim):
    session, _, arm, _ = sim
    goal, _ = _arm_goal(session, np.full(7, 0.05), duration_s=0.1)
    goal.goal_tolerance = [JointTolerance(name=n, position=1e-9) for n in robot.JOINT_NAMES]
    result = _wait(_wait(arm.send_goal_async(goal)).get_result_async()).result
    assert result.error_code == FollowJointTrajectory.Result.GOAL_TOLERANCE_VIOLATED


def test_a_new_goal_replaces_the_running_one(sim):
    session, controllers, arm, _ = sim
    first, _ = _arm_goal(session, np.full(7, 0.1), duration_s=2.0)
    first_handle = _wait(arm.send_goal_async(first))
    second, target = _arm_goal(session, np.full(7, -0.05), duration_s=0.3)
    second_handle = _wait(arm.send_goal_async(second))
    first_result = _wait(first_handle.get_result_async()).result
    assert "replaced" in first_result.error_string
    assert _wait(second_handle.get_result_async()).result.error_code == 0


def test_the_gripper_opens_to_its_goal_and_stalls_on_an_object_or_closes(sim):
    session, _, _, gripper = sim
    goal = GripperCommand.Goal()
    goal.command.position = robot.GRIPPER_OPEN_M
    result = _wait(_wait(gripper.send_goal_async(goal)).get_result_async()).result
    assert result.reached_goal and abs(result.position - robot.GRIPPER_OPEN_M) < 0.003
    goal.command.position = 0.0
    result = _wait(_wait(gripper.send_goal_async(goal)).get_result_async()).result
    assert result.reached_goal or result.stalled
    assert session.world.joint_positions()[-1] < robot.GRIPPER_OPEN_M - 0.01


def test_a_gripper_held_short_of_its_goal_reports_a_stall(sim, monkeypatch):
    """Fingers closing on an object stop short of the set point: the goal ends stalled, and the
    result goes out (a numpy value in it once aborted the node when serialized)."""
    _, controllers, _, gripper = sim
    monkeypatch.setattr(controllers, "_finger_m", lambda: 0.02)
    goal = GripperCommand.Goal()
    goal.command.position = 0.0
    result = _wait(_wait(gripper.send_goal_async(goal)).get_result_async()).result
    assert result.stalled and not result.reached_goal and result.position == 0.02
