"""plan_node in-process: goals over the real action interface, refusals keep the node serving."""

import threading
import time
from dataclasses import replace

import numpy as np
import pytest
import rclpy
import trimesh
from rclpy.action import ActionClient
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from arm_interfaces.action import Manipulate
from arm_interfaces.msg import ReconstructedObject, ReconstructedObjectArray
from arm_planner.plan_node import PlanNode
from arm_ros.common import latched_qos
from arm_ros.conversions.meshes import mesh_to_msg
from arm_ros.conversions.poses import matrix_to_pose
from arm_ros.executors import QueueAwareMultiThreadedExecutor, result_within
from arm_sim import robot


@pytest.fixture(scope="module")
def graph():
    rclpy.init()
    overrides = [
        Parameter("steps", value=5),
        Parameter("settle_s", value=0.0),
        Parameter("controller_interface", value="topic"),  # the trajectory as the tests receive it
    ]
    node = PlanNode(parameter_overrides=overrides)
    node.session.config.push_steps = 0  # pushes too plan `steps` (5) steps
    client = Node("plan_node_test_client")
    executor = QueueAwareMultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    executor.add_node(client)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    received = []
    client.create_subscription(JointTrajectory, "arm/joint_trajectory", received.append, 10)
    action = ActionClient(client, Manipulate, "arm/manipulate")
    assert action.wait_for_server(timeout_sec=10)
    yield node, client, action, received
    node.close()
    executor.shutdown()
    thread.join(timeout=10.0)  # the spin loop ends before the context does: no wait set on a shut-down context
    node.destroy_node()
    client.destroy_node()
    rclpy.try_shutdown()


def _wait(future, timeout=60.0):
    return result_within(future, timeout)


def _send(action, task, target_id, displacement=(0.0, 0.0, 0.0), meshes_stamp_s=0):
    goal = Manipulate.Goal(task=task, target_id=target_id)
    goal.meshes_stamp.sec = meshes_stamp_s
    goal.goal_displacement.x, goal.goal_displacement.y, goal.goal_displacement.z = displacement
    handle = _wait(action.send_goal_async(goal))
    assert handle.accepted
    return _wait(handle.get_result_async()).result


def _publish_inputs(client, joint_positions, object_id=4, stamp_s=0):
    box = trimesh.creation.box(extents=(0.05, 0.05, 0.08))
    T = np.eye(4)
    T[:3, 3] = (0.0, 0.0, 0.04)
    meshes = ReconstructedObjectArray(table_height_m=0.0)
    meshes.header.stamp.sec = stamp_s
    meshes.objects = [
        ReconstructedObject(id=object_id, pose=matrix_to_pose(T), mesh=mesh_to_msg(box.vertices, box.faces))
    ]
    client.create_publisher(ReconstructedObjectArray, "arm/meshes", latched_qos()).publish(meshes)
    joints = client.create_publisher(JointState, "joint_states", 1)
    names = list(robot.JOINT_NAMES) + [robot.FINGER_JOINT_NAMES[0]]
    joints.publish(JointState(name=names, position=list(joint_positions)))
    return joints, names


def test_refusals_then_a_plan(graph):
    node, client, action, received = graph
    result = _send(action, Manipulate.Goal.TASK_GRASP, 4)
    assert not result.success and "no reconstructed objects" in result.message
    joints, names = _publish_inputs(client, list(robot.HOME_Q) + [0.04])
    deadline = time.monotonic() + 10
    while node.meshes_received == 0 or node._joints is None:
        assert time.monotonic() < deadline
        time.sleep(0.05)
    result = _send(action, Manipulate.Goal.TASK_GRASP, 9)
    assert "unknown target id 9" in result.message
    result = _send(action, Manipulate.Goal.TASK_PUSH, 4, (2.0, 0.0, 0.0))
    assert "out of reach" in result.message
    result = _send(action, 17, 4)
    assert "unknown task" in result.message
    result = _send(action, Manipulate.Goal.TASK_PUSH, 4, (0.05, -0.3, 0.0))
    assert len(result.trajectory.points) == 5 and result.trajectory.joint_names == names
    deadline = time.monotonic() + 5
    while not received:
        assert time.monotonic() < deadline
        time.sleep(0.05)
    assert len(received[-1].points) == 5
    joints.publish(JointState(name=names, position=[float("nan")] * 8))
    time.sleep(0.3)
    result = _send(action, Manipulate.Goal.TASK_GRASP, 4)
    assert "invalid" in result.message


def test_closed_loop_replanning_executes_in_chunks(graph):
    node, client, action, received = graph
    _publish_inputs(client, list(robot.HOME_Q) + [0.04])
    time.sleep(0.3)
    config = node.config
    node.config = replace(config, execution="replan", replan_period_s=0.04, max_replans=2)
    try:
        before = len(received)
        result = _send(action, Manipulate.Goal.TASK_GRASP, 4)
    finally:
        node.config = config
    assert result.trajectory.points, result.message
    deadline = time.monotonic() + 5
    while len(received) - before < 3:
        assert time.monotonic() < deadline, "expected one trajectory per chunk"
        time.sleep(0.05)
    chunks = received[before:]
    assert [len(c.points) for c in chunks[:2]] == [2, 2]
    assert len(result.trajectory.points) == sum(len(c.points) for c in chunks)
    # the result is the executed chunks one after another: one trajectory, its times increasing
    times = [p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in result.trajectory.points]
    assert np.all(np.diff(times) > 0)


def _plan_index(positions, part):
    """Where the part's points start in the plan (they must be a contiguous run of it)."""
    points = np.array([p.positions for p in part.points])
    for k in range(len(positions) - len(points) + 1):
        if np.allclose(positions[k : k + len(points)], points):
            return k
    raise AssertionError("a streamed part is not a run of the plan")


def test_streamed_parts_join_into_the_plan(graph):
    node, client, action, received = graph
    _publish_inputs(client, list(robot.HOME_Q) + [0.04])
    time.sleep(0.3)
    config = node.config
    node.config = replace(config, stream_lead_s=0.04, stream_period_s=0.04)
    try:
        before = len(received)
        result = _send(action, Manipulate.Goal.TASK_GRASP, 4)
    finally:
        node.config = config
    positions = np.array([p.positions for p in result.trajectory.points])
    assert len(positions) == 5, result.message
    deadline = time.monotonic() + 5
    while len(received) - before < 3:
        assert time.monotonic() < deadline, "expected the plan in three parts (lead 2 steps, then 2, then 1)"
        time.sleep(0.05)
    parts = received[before:]
    starts = [_plan_index(positions, part) for part in parts]
    assert starts[0] == 0 and len(parts[0].points) == 2
    for k in range(1, len(parts)):  # each part starts where the controller got to: no gap, no skip
        assert starts[k] <= starts[k - 1] + len(parts[k - 1].points)
    assert starts[-1] + len(parts[-1].points) == len(positions)
    assert node.plan_figures["stream_parts"] == len(parts)
    assert node.plan_figures["realtime_factor"] > 0
    assert node.plan_figures["last_plan_twin_objects"] >= 1
    # one time base: a planned point sent in two parts is due at the same clock time in both
    due = {}
    for start, part in zip(starts, parts, strict=True):
        stamp_s = part.header.stamp.sec + 1e-9 * part.header.stamp.nanosec
        assert stamp_s > 0
        for k, point in enumerate(part.points):
            t = stamp_s + point.time_from_start.sec + 1e-9 * point.time_from_start.nanosec
            assert due.setdefault(start + k, t) == pytest.approx(t, abs=1e-5)


def test_execute_mode_holds_back_a_plan_the_twin_did_not_meet(graph):
    node, client, action, received = graph
    _publish_inputs(client, list(robot.HOME_Q) + [0.04])
    time.sleep(0.3)
    config = node.config
    node.config = replace(config, execution="execute")
    try:
        before = len(received)
        result = _send(action, Manipulate.Goal.TASK_GRASP, 4)  # 5 steps: never met
    finally:
        node.config = config
    assert not result.success and "not executed" in result.message
    assert len(result.trajectory.points) == 5
    time.sleep(0.5)
    assert len(received) == before


def test_a_plan_only_goal_returns_the_plan_and_sends_nothing(graph):
    node, client, action, received = graph
    _publish_inputs(client, list(robot.HOME_Q) + [0.04])
    time.sleep(0.3)
    assert node.config.execution == "stream"
    before = len(received)
    goal = Manipulate.Goal(task=Manipulate.Goal.TASK_GRASP, target_id=4, plan_only=True)
    result = _wait(_wait(action.send_goal_async(goal)).get_result_async()).result
    assert len(result.trajectory.points) == 5, result.message
    assert result.controller_error_code == Manipulate.Result.EXECUTION_NOT_SENT
    time.sleep(0.5)
    assert len(received) == before


def test_a_goal_repeating_a_dry_run_the_twin_met_executes_that_plan(graph):
    node, client, action, received = graph
    _publish_inputs(client, list(robot.HOME_Q) + [0.04])
    time.sleep(0.3)
    request = node.session.request

    def met_in_the_twin(*args, **kwargs):  # 5 steps never meet a grasp: take this one as met
        outcome = request(*args, **kwargs)
        outcome.success = True
        return outcome

    node.session.request = met_in_the_twin
    try:
        dry = Manipulate.Goal(task=Manipulate.Goal.TASK_GRASP, target_id=4, plan_only=True)
        planned = _wait(_wait(action.send_goal_async(dry)).get_result_async()).result
    finally:
        node.session.request = request
    before = len(received)
    result = _send(action, Manipulate.Goal.TASK_GRASP, 4)
    assert "executing the plan of the dry run" in result.message
    deadline = time.monotonic() + 5
    while len(received) == before:
        assert time.monotonic() < deadline, "the dry run's plan was not sent"
        time.sleep(0.05)
    sent = np.array([p.positions for p in received[-1].points])
    assert np.array_equal(sent, np.array([p.positions for p in planned.trajectory.points]))
    result = _send(action, Manipulate.Goal.TASK_GRASP, 4)
    assert "dry run" not in result.message, "a dry run's plan is executed once"


def test_of_several_dry_runs_any_one_may_be_executed(graph):
    node, client, action, received = graph
    _publish_inputs(client, list(robot.HOME_Q) + [0.04])
    time.sleep(0.3)
    request = node.session.request

    def met_in_the_twin(*args, **kwargs):
        outcome = request(*args, **kwargs)
        outcome.success = True
        return outcome

    node.session.request = met_in_the_twin
    try:
        planned = {}
        for task, displacement_xy in (
            (Manipulate.Goal.TASK_GRASP, (0.0, 0.0)),
            (Manipulate.Goal.TASK_PUSH, (0.05, -0.3)),
        ):
            dry = Manipulate.Goal(task=task, target_id=4, plan_only=True)
            dry.goal_displacement.x, dry.goal_displacement.y = displacement_xy
            result = _wait(_wait(action.send_goal_async(dry)).get_result_async()).result
            assert not result.held_in_twin, "5 steps: stopped by the budget, not by a held outcome"
            planned[task] = np.array([p.positions for p in result.trajectory.points])
    finally:
        node.session.request = request
    before = len(received)
    result = _send(action, Manipulate.Goal.TASK_GRASP, 4)  # the earlier of the two dry runs
    assert "executing the plan of the dry run" in result.message
    deadline = time.monotonic() + 5
    while len(received) == before:
        assert time.monotonic() < deadline, "the dry run's plan was not sent"
        time.sleep(0.05)
    assert np.array_equal(np.array([p.positions for p in received[-1].points]), planned[Manipulate.Goal.TASK_GRASP])


def test_goal_plans_on_the_meshes_its_stamp_names(graph):
    node, client, action, _ = graph
    for object_id, stamp_s in ((4, 100), (7, 101)):  # the same box, relabelled in a later frame
        received = node.meshes_received
        _publish_inputs(client, list(robot.HOME_Q) + [0.04], object_id=object_id, stamp_s=stamp_s)
        deadline = time.monotonic() + 10
        while node.meshes_received == received:  # one at a time: the subscription keeps only the last
            assert time.monotonic() < deadline
            time.sleep(0.05)
    result = _send(action, Manipulate.Goal.TASK_PUSH, 4, (0.05, -0.3, 0.0), meshes_stamp_s=100)
    assert len(result.trajectory.points) == 5, result.message
    assert "unknown target id 4" in _send(action, Manipulate.Goal.TASK_GRASP, 4).message  # latest: stamp 101
    result = _send(action, Manipulate.Goal.TASK_GRASP, 4, meshes_stamp_s=99)
    assert "no /arm/meshes array stamped 99000000000 ns" in result.message


def test_goal_for_an_array_still_in_flight_waits_for_it(graph):
    """A client that picked its target from an array this node has not received yet is served once
    the array arrives (within plan_node.MESHES_ARRIVAL_WAIT_S), not refused."""
    node, client, action, _ = graph
    goal = Manipulate.Goal(task=Manipulate.Goal.TASK_PUSH, target_id=9)
    goal.meshes_stamp.sec = 200
    goal.goal_displacement.x, goal.goal_displacement.y = 0.05, -0.3
    handle = _wait(action.send_goal_async(goal))
    assert handle.accepted
    result_future = handle.get_result_async()
    time.sleep(0.3)  # the goal is waiting; now the array it names arrives
    _publish_inputs(client, list(robot.HOME_Q) + [0.04], object_id=9, stamp_s=200)
    result = _wait(result_future).result
    assert len(result.trajectory.points) == 5, result.message
