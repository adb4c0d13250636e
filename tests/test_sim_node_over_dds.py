"""sim_node in its own process, talked to over real DDS."""

import numpy as np
from builtin_interfaces.msg import Duration
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import CameraInfo, Image, JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from arm_interfaces.msg import ReconstructedObjectArray
from arm_ros.common import latched_qos, sensor_qos
from arm_ros.conversions.images import K_from_camera_info, depth_to_metres, image_to_numpy
from arm_ros.conversions.poses import pose_to_matrix
from arm_sim import robot

from ros_helpers import spin_until, start_node


def test_sim_node_publishes_frames_truth_and_executes_trajectories(ros_node, tmp_path):
    sim = start_node("sim", tmp_path, params={"n_objects": 4, "camera_rate_hz": 4.0})
    got = {}
    qos = sensor_qos("best_effort")
    for topic, kind in [
        ("camera/color/image_raw", Image),
        ("camera/depth/image_raw", Image),
        ("camera/camera_info", CameraInfo),
        ("camera/pose", PoseStamped),
        ("sim/ground_truth/labels", Image),
    ]:
        ros_node.create_subscription(kind, topic, lambda m, t=topic: got.__setitem__(t, m), qos)
    ros_node.create_subscription(JointState, "joint_states", lambda m: got.__setitem__("joints", m), 10)
    ros_node.create_subscription(
        ReconstructedObjectArray, "sim/ground_truth/objects", lambda m: got.__setitem__("truth", m), latched_qos()
    )
    try:
        assert spin_until(ros_node, lambda: len(got) == 7, 60.0), f"missing topics, got {sorted(got)}"
        rgb = image_to_numpy(got["camera/color/image_raw"])
        depth = depth_to_metres(got["camera/depth/image_raw"])
        labels = image_to_numpy(got["sim/ground_truth/labels"])
        assert rgb.shape == (480, 640, 3) and depth.shape == (480, 640) and labels.dtype == np.uint16
        assert np.isclose(K_from_camera_info(got["camera/camera_info"])[1, 1], 240 / np.tan(np.deg2rad(22.5)))
        assert np.allclose(pose_to_matrix(got["camera/pose"].pose)[:3, 3], (0.7, 0.0, 0.5))
        truth = got["truth"]
        assert 3 <= len(truth.objects) <= 4 and all(len(o.convex_parts) > 0 for o in truth.objects)
        assert set(np.unique(labels)) - {0} <= {o.id for o in truth.objects}

        goal = robot.HOME_Q + 0.25
        trajectory = JointTrajectory(joint_names=list(robot.JOINT_NAMES))
        trajectory.points = [JointTrajectoryPoint(positions=goal.tolist(), time_from_start=Duration(sec=1))]
        publisher = ros_node.create_publisher(JointTrajectory, "arm/joint_trajectory", 10)
        assert spin_until(ros_node, lambda: publisher.get_subscription_count() > 0, 10.0)
        publisher.publish(trajectory)

        def reached():
            q = np.array(got["joints"].position[:7])
            return np.max(np.abs(q - goal)) < 0.02

        assert spin_until(ros_node, reached, 30.0), f"joints at {got['joints'].position[:7]}, goal {goal}"
    finally:
        assert sim.stop() == 0, sim.log()[-2000:]
