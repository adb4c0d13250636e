"""segmentation_node in its own process, fed over real DDS by this test."""

import threading
import time

import numpy as np
import pytest

from arm_ros.common import use_private_domain

use_private_domain()

import rclpy  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from rclpy.action import ActionClient, ActionServer  # noqa: E402
from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from seg_fixtures import Box, add_noise, look_at, render  # noqa: E402
from sensor_msgs.msg import CameraInfo, Image, PointCloud2  # noqa: E402
from std_msgs.msg import Header  # noqa: E402

from arm_interfaces.action import Manipulate  # noqa: E402
from arm_interfaces.msg import SegmentedFrame  # noqa: E402
from arm_ros.conversions.clouds import labelled_cloud_to_numpy  # noqa: E402
from arm_ros.conversions.images import camera_info_from_K, image_to_numpy, numpy_to_image  # noqa: E402
from arm_ros.conversions.poses import matrix_to_pose, matrix_to_transform_msg, pose_to_matrix  # noqa: E402
from arm_ros.processes import NodeProcess, executable, node_built  # noqa: E402
from arm_ros.tf import TfListener, TfPublisher  # noqa: E402
from arm_segmentation.metrics import segmentation_metrics  # noqa: E402

CAMERA = look_at((-0.45, 0.1, 0.6), (0.05, 0.0, 0.0))


def spin_until(node, predicate, timeout_s):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
        if predicate():
            return True
    return predicate()


@pytest.fixture
def probe():
    if not node_built("segmentation"):
        pytest.fail(f"segmentation_node is not built ({executable('segmentation')}); run `make setup`")
    rclpy.init()
    node = rclpy.create_node("segmentation_probe")
    yield node
    node.destroy_node()
    rclpy.try_shutdown()


def frame_messages(stamp_s, rgb, depth, K, labels=None):
    def header(frame_id="camera_color_optical_frame"):
        h = Header(frame_id=frame_id)
        h.stamp.sec, h.stamp.nanosec = int(stamp_s), int(round((stamp_s % 1) * 1e9))
        return h

    pose = PoseStamped(header=header("world"), pose=matrix_to_pose(CAMERA))
    msgs = [
        numpy_to_image(rgb, "rgb8", header()),
        numpy_to_image(depth, "32FC1", header()),
        camera_info_from_K(K, depth.shape[1], depth.shape[0], header()),
        pose,
    ]
    if labels is not None:
        msgs.append(numpy_to_image(labels, "16UC1", header()))
    return msgs


@pytest.mark.slow
@pytest.mark.parametrize("ground_truth", [False, True])
def test_node_segments_synchronized_frames_and_survives_bad_ones(probe, ground_truth, tmp_path):
    boxes = [
        Box((0.0, -0.05, 0.04), (0.04, 0.05, 0.04), 0.0, (200, 40, 40)),
        Box((0.0, 0.05, 0.04), (0.04, 0.05, 0.04), 0.0, (40, 170, 60)),
    ]
    rgb, depth, gt, K = render(boxes, CAMERA)
    depth = add_noise(depth, np.random.default_rng(0))
    node = NodeProcess(
        "segmentation",
        tmp_path / "segmentation.log",
        params={"use_ground_truth_masks": ground_truth, "image_reliability": "reliable"},
    )
    got = {"frames": [], "overlay": [], "diag": []}
    probe.create_subscription(SegmentedFrame, "arm/segmented_frame", got["frames"].append, 10)
    probe.create_subscription(Image, "arm/segmentation/overlay", got["overlay"].append, 10)
    probe.create_subscription(DiagnosticArray, "diagnostics", got["diag"].append, 10)
    topics = [
        (Image, "camera/color/image_raw"),
        (Image, "camera/depth/image_raw"),
        (CameraInfo, "camera/camera_info"),
        (PoseStamped, "camera/pose"),
        (Image, "sim/ground_truth/labels"),
    ]
    publishers = [probe.create_publisher(kind, topic, 10) for kind, topic in topics[: 5 if ground_truth else 4]]
    try:
        assert spin_until(probe, lambda: all(p.get_subscription_count() > 0 for p in publishers), 30.0)

        def send(msgs, gap_s=0.0):
            for p, m in zip(publishers, msgs, strict=True):
                p.publish(m)
                rclpy.spin_once(probe, timeout_sec=gap_s)

        def diagnostics():
            return [
                {kv.key: kv.value for kv in s.values}
                for d in got["diag"]
                for s in d.status
                if "segmentation_node" in s.name
            ]

        def rejected_because(reason):
            # a frame sent again is processed again, so the status message, not the count, tells
            # which bad frame was rejected
            return lambda: any(
                reason in s.message for d in got["diag"] for s in d.status if "segmentation_node" in s.name
            )

        def deliver(msgs, done, tries=3):
            # subscriptions keep only the latest message (latest-frame processing): resend if one was replaced
            for _ in range(tries):
                send(msgs, 0.05)
                if spin_until(probe, done, 3.0):
                    return True
            return False

        labels = gt if ground_truth else None
        bad = frame_messages(1.0, rgb, depth, K, labels)
        bad[0] = numpy_to_image(rgb[:-4], "rgb8", bad[0].header)  # rgb smaller than depth
        assert deliver(bad, rejected_because("but depth is")), diagnostics()
        odd = frame_messages(2.0, rgb, depth, K, labels)
        odd[1].encoding = "64FC1"  # unknown depth encoding
        assert deliver(odd, rejected_because("depth encoding '64FC1' not supported")), diagnostics()
        unsynced = frame_messages(3.0, rgb, depth, K, labels)
        unsynced[3].header.stamp.sec = 9  # pose 6 s away from the images: never matched
        send(unsynced, 0.05)
        spin_until(probe, lambda: False, 1.0)
        assert got["frames"] == [] and got["overlay"] == []

        assert deliver(frame_messages(10.0, rgb, depth, K, labels), lambda: got["frames"] and got["overlay"])
        frame = got["frames"][0]
        assert frame.header.stamp.sec == 10 and frame.world_frame_id == "world"
        predicted = image_to_numpy(frame.labels)
        if ground_truth:
            assert np.array_equal(predicted, gt)
        else:
            assert segmentation_metrics(predicted, gt)["overlap_f"] > 0.9
        assert spin_until(probe, lambda: any(int(d.get("frames_published", 0)) >= 1 for d in diagnostics()), 5.0)
    finally:
        code = node.stop(timeout_s=10.0)
    output = node.log()
    assert code == 0, output
    assert "rejected" in output


@pytest.mark.slow
def test_node_estimates_the_camera_pose_without_a_pose_topic(probe, tmp_path):
    rgb, depth, gt, K = render(
        [
            Box((0.0, -0.05, 0.04), (0.04, 0.05, 0.04), 0.0, (200, 40, 40)),
            Box((0.0, 0.05, 0.04), (0.04, 0.05, 0.04), 0.0, (40, 170, 60)),
        ],
        CAMERA,
    )
    depth = add_noise(depth, np.random.default_rng(0))
    node = NodeProcess(
        "segmentation",
        tmp_path / "segmentation.log",
        params={"camera_pose_source": "estimate", "image_reliability": "reliable"},
    )
    got = {"frames": [], "poses": [], "diag": [], "clouds": []}
    probe.create_subscription(SegmentedFrame, "arm/segmented_frame", got["frames"].append, 10)
    probe.create_subscription(PoseStamped, "camera/pose/estimated", got["poses"].append, 10)
    probe.create_subscription(PointCloud2, "arm/segmentation/points", got["clouds"].append, 10)
    tf = TfListener(probe)
    probe.create_subscription(DiagnosticArray, "diagnostics", got["diag"].append, 10)
    topics = [(Image, "camera/color/image_raw"), (Image, "camera/depth/image_raw"), (CameraInfo, "camera/camera_info")]
    publishers = [probe.create_publisher(kind, topic, 10) for kind, topic in topics]

    def pose_statuses():
        return [s for d in got["diag"] for s in d.status if "camera_pose_estimate" in s.name]

    def deliver(msgs, done, tries=5):
        # generous waits: a loaded CPU delays the node's first estimate and its 1 s diagnostics
        for _ in range(tries):
            for p, m in zip(publishers, msgs, strict=True):
                p.publish(m)
                rclpy.spin_once(probe, timeout_sec=0.05)
            if spin_until(probe, done, 5.0):
                return True
        return False

    try:
        assert spin_until(probe, lambda: all(p.get_subscription_count() > 0 for p in publishers), 30.0)
        flat = np.random.default_rng(1).uniform(0.5, 3.0, depth.shape).astype(np.float32)  # no plane in it
        no_plane = frame_messages(1.0, rgb, flat, K)[:3]
        assert deliver(no_plane, lambda: any("no camera pose: no plane" in s.message for s in pose_statuses()))
        assert pose_statuses()[-1].level == DiagnosticStatus.ERROR and got["frames"] == []

        assert deliver(frame_messages(2.0, rgb, depth, K)[:3], lambda: got["frames"] and got["poses"])
        frame, pose = got["frames"][0], got["poses"][0]
        assert frame.world_frame_id == "table" and pose.header.frame_id == "table"
        # the estimate on /tf: the table frame under the camera's optical frame
        assert spin_until(probe, lambda: tf.lookup("table", "camera_color_optical_frame") is not None, 5.0)
        assert np.allclose(tf.lookup("table", "camera_color_optical_frame"), pose_to_matrix(pose.pose), atol=1e-6)
        assert pose.header.stamp.sec == 2 and abs(pose.pose.position.z - CAMERA[2, 3]) < 0.005
        assert frame.camera_pose == pose.pose
        labels = image_to_numpy(frame.labels)
        assert segmentation_metrics(labels, gt)["overlap_f"] > 0.9
        # the objects' cloud: one point per object pixel with depth, in the optical frame, labelled
        assert spin_until(probe, lambda: got["clouds"], 5.0)
        cloud = got["clouds"][0]
        points, colours, cloud_labels = labelled_cloud_to_numpy(cloud)
        assert cloud.header.frame_id == frame.header.frame_id
        assert 0.9 * np.count_nonzero(labels) < len(points) <= np.count_nonzero(labels)
        assert set(np.unique(cloud_labels)) == set(frame.instance_ids)
        assert np.all((points[:, 2] > 0.3) & (points[:, 2] < 1.0)) and colours.shape == (len(points), 3)
        assert spin_until(probe, lambda: pose_statuses() and pose_statuses()[-1].level == DiagnosticStatus.OK, 10.0)
        values = {kv.key: kv.value for kv in pose_statuses()[-1].values}
        assert float(values["inlier_fraction"]) > 0.5 and int(values["failures"]) >= 1  # resends count too
    finally:
        code = node.stop(timeout_s=10.0)
    output = node.log()
    assert code == 0, output
    assert "camera pose: no plane" in output


@pytest.mark.slow
def test_node_takes_the_camera_pose_from_tf(probe, tmp_path):
    """camera_pose_source tf: T_world_camera is the chain world -> base_link -> camera optical frame on
    /tf_static and /tf, as a robot's URDF and a calibration publish it."""
    rgb, depth, gt, K = render(
        [Box((0.0, -0.05, 0.04), (0.04, 0.05, 0.04), 0.0, (200, 40, 40)), Box((0.12, 0.0, 0.06), (0.03, 0.03, 0.06))],
        CAMERA,
    )
    node = NodeProcess(
        "segmentation",
        tmp_path / "segmentation.log",
        params={"camera_pose_source": "tf", "world_frame": "world", "image_reliability": "reliable"},
    )
    got = {"frames": []}
    probe.create_subscription(SegmentedFrame, "arm/segmented_frame", got["frames"].append, 10)
    topics = [(Image, "camera/color/image_raw"), (Image, "camera/depth/image_raw"), (CameraInfo, "camera/camera_info")]
    publishers = [probe.create_publisher(kind, topic, 10) for kind, topic in topics]
    tf = TfPublisher(probe)
    T_world_base = np.eye(4)
    T_world_base[:3, 3] = (-0.55, 0.0, 0.0)
    try:
        assert spin_until(probe, lambda: all(p.get_subscription_count() > 0 for p in publishers), 30.0)
        tf.send_static([matrix_to_transform_msg(T_world_base, "world", "base_link", Header().stamp)])
        T_base_camera = np.linalg.inv(T_world_base) @ CAMERA
        camera = matrix_to_transform_msg(T_base_camera, "base_link", "camera_color_optical_frame", Header().stamp)
        for attempt in range(5):
            tf.send([camera])
            for p, m in zip(publishers, frame_messages(1.0 + attempt, rgb, depth, K)[:3], strict=True):
                p.publish(m)
            if spin_until(probe, lambda: got["frames"], 5.0):
                break
        assert got["frames"], node.log()[-2000:]
        frame = got["frames"][0]
        assert frame.world_frame_id == "world"
        assert np.allclose(pose_to_matrix(frame.camera_pose), CAMERA, atol=1e-6)
        assert segmentation_metrics(image_to_numpy(frame.labels), gt)["overlap_f"] > 0.9
    finally:
        code = node.stop(timeout_s=10.0)
    assert code == 0, node.log()


@pytest.mark.slow
def test_camera_frames_are_dropped_while_the_planner_serves_a_goal(probe, tmp_path):
    """A real Manipulate action server (in this process) holds a goal open: frames sent meanwhile are
    not segmented; once the goal ends, the next frame is."""
    rgb, depth, gt, K = render([Box((0.0, 0.0, 0.04), (0.04, 0.05, 0.04), 0.0, (200, 40, 40))], CAMERA)
    node = NodeProcess("segmentation", tmp_path / "segmentation.log", params={"image_reliability": "reliable"})
    got = {"frames": [], "diag": []}
    probe.create_subscription(SegmentedFrame, "arm/segmented_frame", got["frames"].append, 10)
    probe.create_subscription(DiagnosticArray, "diagnostics", got["diag"].append, 10)
    publishers = [
        probe.create_publisher(kind, topic, 10)
        for kind, topic in [
            (Image, "camera/color/image_raw"),
            (Image, "camera/depth/image_raw"),
            (CameraInfo, "camera/camera_info"),
            (PoseStamped, "camera/pose"),
        ]
    ]
    release = threading.Event()

    def execute(goal_handle):
        release.wait(60.0)
        goal_handle.succeed()
        return Manipulate.Result(success=True)

    planner = rclpy.create_node("planner_stand_in")
    server = ActionServer(planner, Manipulate, "arm/manipulate", execute)
    spinner = MultiThreadedExecutor()  # execute blocks: the server spins on its own
    spinner.add_node(planner)
    threading.Thread(target=spinner.spin, daemon=True).start()
    action_client = ActionClient(probe, Manipulate, "arm/manipulate")

    def status():
        values = [{kv.key: kv.value for kv in s.values} for d in got["diag"] for s in d.status]
        return [v for v in values if "messages_skipped_for_goals" in v]

    def send(stamp_s):
        for p, m in zip(publishers, frame_messages(stamp_s, rgb, depth, K), strict=True):
            p.publish(m)
            rclpy.spin_once(probe, timeout_sec=0.05)

    try:
        assert spin_until(probe, lambda: all(p.get_subscription_count() > 0 for p in publishers), 30.0)
        assert action_client.wait_for_server(timeout_sec=10.0)
        action_client.send_goal_async(Manipulate.Goal(task=0, target_id=1))
        assert spin_until(probe, lambda: status() and status()[-1]["paused_for_goal"] == "True", 20.0)
        for stamp_s in (1.0, 2.0, 3.0):
            send(stamp_s)
        assert spin_until(probe, lambda: int(status()[-1]["messages_skipped_for_goals"]) >= 12, 10.0)
        assert got["frames"] == []
        release.set()
        assert spin_until(probe, lambda: status()[-1]["paused_for_goal"] == "False", 20.0)
        for stamp_s in (10.0, 11.0, 12.0):  # latest-frame processing: resend until one is segmented
            send(stamp_s)
            if spin_until(probe, lambda: got["frames"], 5.0):
                break
        assert got["frames"] and got["frames"][0].header.stamp.sec >= 10
        assert int(status()[-1]["goal_pauses"]) == 1
    finally:
        release.set()
        code = node.stop(timeout_s=10.0)
        spinner.shutdown()
        server.destroy()
        action_client.destroy()
        planner.destroy_node()
    assert code == 0, node.log()
