"""plan_node executing through ros2_control's actions (FollowJointTrajectory for the arm, GripperCommand
for the gripper), served by the sim's controllers; the executed result reaches the goal's result."""

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
from std_msgs.msg import Header

from arm_interfaces.action import Manipulate
from arm_interfaces.msg import ReconstructedObject, ReconstructedObjectArray
from arm_planner.plan_node import PlanNode
from arm_ros.common import latched_qos
from arm_ros.conversions.meshes import mesh_to_msg
from arm_ros.conversions.poses import matrix_to_pose
from arm_ros.conversions.stamps import ns_to_time
from arm_ros.executors import QueueAwareMultiThreadedExecutor, result_within
from arm_sim import robot
from arm_sim.controllers import SimControllers
from arm_sim.core import SimSession

TICK_S = 0.02


@pytest.fixture(scope="module")
def graph():
    rclpy.init()
    session = SimSession(seed=0, n_objects=3, width=64, height=48, depth_noise=False)
    host = Node("sim_controllers_host")
    controllers = SimControllers(
        host, session, "arm_controller", "gripper_controller", lambda: session.time_s, lambda frame: Header()
    )
    joints = host.create_publisher(JointState, "joint_states", 10)
    names = list(robot.JOINT_NAMES) + [robot.FINGER_JOINT_NAMES[0]]

    def tick():
        session.step(TICK_S)
        controllers.tick()
        joints.publish(JointState(name=names, position=session.world.joint_positions().tolist()))

    host.create_timer(TICK_S, tick)
    overrides = [
        Parameter("steps", value=10),
        Parameter("settle_s", value=0.0),
        Parameter("execution", value="stream"),
        Parameter("observe_timeout_s", value=5.0),
    ]
    node = PlanNode(parameter_overrides=overrides)
    client = Node("plan_node_ros2_control_client")
    executor = QueueAwareMultiThreadedExecutor(num_threads=5)
    for n in (host, node, client):
        executor.add_node(n)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    action = ActionClient(client, Manipulate, "arm/manipulate")
    assert action.wait_for_server(timeout_sec=10)
    assert not node.controllers.missing_servers(10.0)
    yield session, controllers, node, client, action
    node.close()
    controllers.close()
    executor.shutdown()
    thread.join(timeout=10.0)
    for n in (host, node, client):
        n.destroy_node()
    rclpy.try_shutdown()


def _wait(future, timeout=60.0):
    return result_within(future, timeout)


def _meshes(client, centre, stamp_ns):
    box = trimesh.creation.box(extents=(0.05, 0.05, 0.08))
    T = np.eye(4)
    T[:3, 3] = centre
    msg = ReconstructedObjectArray(table_height_m=0.0)
    msg.header.stamp = ns_to_time(stamp_ns)
    msg.objects = [ReconstructedObject(id=4, pose=matrix_to_pose(T), mesh=mesh_to_msg(box.vertices, box.faces))]
    return msg


def test_the_plan_is_executed_by_the_controllers_and_the_outcome_observed(graph):
    session, controllers, node, client, action = graph
    meshes = client.create_publisher(ReconstructedObjectArray, "arm/meshes", latched_qos())
    start_ns = client.get_clock().now().nanoseconds
    meshes.publish(_meshes(client, (0.0, 0.0, 0.04), start_ns))
    time.sleep(0.5)
    arm_goals, gripper_goals = controllers.goals["arm"], controllers.goals["gripper"]
    handle = _wait(action.send_goal_async(Manipulate.Goal(task=Manipulate.Goal.TASK_GRASP, target_id=4)))
    assert handle.accepted
    result_future = handle.get_result_async()
    # a frame after the motion shows the box 8 cm higher
    deadline = time.monotonic() + 60
    while controllers.goals["arm"] == arm_goals:
        assert time.monotonic() < deadline, "no trajectory goal reached the arm controller"
        time.sleep(0.05)
    time.sleep(1.0)
    meshes.publish(_meshes(client, (0.0, 0.0, 0.12), client.get_clock().now().nanoseconds + int(5e9)))
    result = _wait(result_future).result
    assert result.trajectory.points, result.message
    assert result.controller_error_code == 0, result.controller_message
    assert "gripper" in result.controller_message
    assert controllers.goals["gripper"] > gripper_goals  # the plan opens or closes the gripper
    assert result.displacement_observed, result.controller_message
    moved = (result.observed_displacement.x, result.observed_displacement.y, result.observed_displacement.z)
    assert np.allclose(moved, (0.0, 0.0, 0.08), atol=1e-6)


def test_with_no_controller_running_the_result_says_so(graph):
    session, controllers, node, client, action = graph
    from arm_planner.controller_client import ControllerClient

    meshes = client.create_publisher(ReconstructedObjectArray, "arm/meshes", latched_qos())
    meshes.publish(_meshes(client, (0.0, 0.0, 0.04), client.get_clock().now().nanoseconds + int(10e9)))
    time.sleep(0.5)  # the box at rest again (the last test's frame showed it lifted)
    real = node.controllers
    node.controllers = ControllerClient(node, "absent_arm_controller", "absent_gripper", node.finger_joint, 10.0)
    config = node.config
    node.config = replace(config, execution_margin_s=0.5)
    try:
        handle = _wait(action.send_goal_async(Manipulate.Goal(task=Manipulate.Goal.TASK_GRASP, target_id=4)))
        result = _wait(handle.get_result_async()).result
    finally:
        node.controllers.close()
        node.controllers, node.config = real, config
    assert result.trajectory.points
    assert result.controller_error_code == Manipulate.Result.EXECUTION_TIMED_OUT
    assert "absent_arm_controller" in result.controller_message
