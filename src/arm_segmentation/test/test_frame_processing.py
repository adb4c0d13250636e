import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from seg_fixtures import Box, add_noise, look_at, render
from std_msgs.msg import Header

from arm_ros.conversions.images import camera_info_from_K, image_to_numpy, numpy_to_image
from arm_ros.conversions.poses import matrix_to_pose
from arm_segmentation.frame_processing import FrameError, segment_messages
from arm_segmentation.metrics import segmentation_metrics

CAMERA = look_at((-0.45, 0.1, 0.6), (0.05, 0.0, 0.0))
BOXES = [
    Box((0.0, -0.05, 0.04), (0.04, 0.05, 0.04), 0.0, (200, 40, 40)),
    Box((0.0, 0.05, 0.04), (0.04, 0.05, 0.04), 0.0, (40, 170, 60)),
]


@pytest.fixture(scope="module")
def scene():
    rgb, depth, gt, K = render(BOXES, CAMERA)
    return rgb, add_noise(depth, np.random.default_rng(0)), gt, K


def messages(rgb, depth, K, depth_encoding="32FC1"):
    header = Header(frame_id="camera_color_optical_frame")
    header.stamp.sec, header.stamp.nanosec = 12, 500
    if depth_encoding == "16UC1":
        depth_msg = numpy_to_image(np.round(depth * 1000).astype(np.uint16), "16UC1", header)
    else:
        depth_msg = numpy_to_image(depth, depth_encoding, header)
    rgb_msg = numpy_to_image(rgb, "rgb8", header)
    info = camera_info_from_K(K, depth.shape[1], depth.shape[0], header)
    pose = PoseStamped(pose=matrix_to_pose(CAMERA))
    pose.header.frame_id = "world"
    return rgb_msg, depth_msg, info, pose


def test_metres_and_millimetres_give_the_same_segmentation(scene):
    rgb, depth, gt, K = scene
    frame_m, overlay = segment_messages(*messages(rgb, depth, K, "32FC1"))
    frame_mm, _ = segment_messages(*messages(rgb, depth, K, "16UC1"))
    labels_m = image_to_numpy(frame_m.labels)
    labels_mm = image_to_numpy(frame_mm.labels)
    assert segmentation_metrics(labels_m, gt)["overlap_f"] > 0.9
    assert segmentation_metrics(labels_mm, labels_m)["overlap_f"] > 0.97
    assert list(frame_m.instance_ids) == sorted(set(np.unique(labels_m)) - {0})
    assert frame_m.header.stamp.sec == 12 and frame_m.world_frame_id == "world"
    assert frame_m.depth.encoding == "32FC1" and frame_m.labels.encoding == "16UC1"
    assert np.allclose(image_to_numpy(frame_mm.depth), np.round(depth * 1000) / 1000, atol=1e-6)
    assert overlay.encoding == "rgb8" and (overlay.height, overlay.width) == depth.shape


def test_ground_truth_masks_pass_through(scene):
    rgb, depth, gt, K = scene
    labels_msg = numpy_to_image(gt, "16UC1")
    frame, _ = segment_messages(*messages(rgb, depth, K), labels_msg)
    assert np.array_equal(image_to_numpy(frame.labels), gt)
    assert list(frame.instance_ids) == [1, 2]


def test_bgr_input_is_converted(scene):
    rgb, depth, gt, K = scene
    rgb_msg, depth_msg, info, pose = messages(rgb, depth, K)
    bgr_msg = numpy_to_image(rgb[..., ::-1], "bgr8", rgb_msg.header)
    frame, _ = segment_messages(bgr_msg, depth_msg, info, pose)
    assert np.array_equal(image_to_numpy(frame.rgb), rgb)


@pytest.mark.parametrize(
    "problem",
    [
        "rgb_encoding",
        "depth_encoding",
        "size",
        "info_size",
        "zero_K",
        "nan_pose",
        "short_data",
        "labels_size",
        "labels_encoding",
    ],
)
def test_malformed_frames_raise_frame_error(scene, problem):
    rgb, depth, gt, K = scene
    rgb_msg, depth_msg, info, pose = messages(rgb, depth, K)
    labels_msg = None
    if problem == "rgb_encoding":
        rgb_msg.encoding = "yuv422"
    elif problem == "depth_encoding":
        depth_msg = numpy_to_image(depth.astype(np.float32), "32FC1", depth_msg.header)
        depth_msg.encoding = "64FC1"
    elif problem == "size":
        rgb_msg = numpy_to_image(rgb[:-2], "rgb8", rgb_msg.header)
    elif problem == "info_size":
        info.width = 320
    elif problem == "zero_K":
        info.k = [0.0] * 9
    elif problem == "nan_pose":
        pose.pose.position.x = float("nan")
    elif problem == "short_data":
        depth_msg.data = bytes(depth_msg.data)[:100]
    elif problem == "labels_size":
        labels_msg = numpy_to_image(gt[:-1], "16UC1")
    elif problem == "labels_encoding":
        labels_msg = numpy_to_image(gt.astype(np.uint8), "mono8")
    with pytest.raises(FrameError):
        segment_messages(rgb_msg, depth_msg, info, pose, labels_msg)


def test_invalid_depth_values_still_publish(scene):
    rgb, depth, gt, K = scene
    bad = depth.copy()
    bad[::3, ::3] = np.nan
    bad[1::5, ::2] = -np.inf
    frame, _ = segment_messages(*messages(rgb, bad, K))
    stored = image_to_numpy(frame.depth)
    assert np.all(np.isfinite(stored)) and stored.min() >= 0
    assert len(frame.instance_ids) == 2
