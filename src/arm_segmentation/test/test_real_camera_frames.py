"""Frames as real RGB-D drivers publish them: other resolutions, 4-channel colour, millimetre depth,
lens distortion, no camera pose."""

import cv2
import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from seg_fixtures import Box, add_noise, look_at, render
from std_msgs.msg import Header

from arm_ros.conversions.images import camera_info_from_K, image_to_numpy, numpy_to_image
from arm_ros.conversions.poses import matrix_to_pose
from arm_segmentation.camera_pose_estimate import estimate_camera_pose
from arm_segmentation.frame_processing import FrameError, decode_camera_frame, segment_frame, segment_messages
from arm_segmentation.metrics import segmentation_metrics
from arm_segmentation.segmentation import reference_factor, segment_detailed

CAMERA = look_at((-0.45, 0.1, 0.6), (0.05, 0.0, 0.0))
BOXES = [
    Box((0.0, -0.05, 0.04), (0.04, 0.05, 0.04), 0.0, (200, 40, 40)),
    Box((0.0, 0.05, 0.04), (0.04, 0.05, 0.04), 0.0, (40, 170, 60)),
    Box((0.12, 0.0, 0.06), (0.03, 0.03, 0.06), 0.4, (40, 60, 200)),
]
PLUMB_BOB = [-0.12, 0.05, 0.0008, -0.0006, -0.01]


def header():
    h = Header(frame_id="camera_color_optical_frame")
    h.stamp.sec = 5
    return h


def messages(rgb, depth_m, K, colour="rgb8", distortion=("plumb_bob", [0.0] * 5)):
    h = header()
    if colour in ("bgra8", "rgba8"):
        alpha = np.full(rgb.shape[:2] + (1,), 255, np.uint8)
        pixels = np.concatenate([rgb[..., ::-1] if colour == "bgra8" else rgb, alpha], axis=2)
        rgb_msg = numpy_to_image(pixels.reshape(rgb.shape[0], -1), "mono8", h)
        rgb_msg.encoding, rgb_msg.width = colour, rgb.shape[1]
    else:
        rgb_msg = numpy_to_image(rgb[..., ::-1] if colour == "bgr8" else rgb, colour, h)
    depth_msg = numpy_to_image(np.round(depth_m * 1000).astype(np.uint16), "16UC1", h)
    info = camera_info_from_K(K, depth_m.shape[1], depth_m.shape[0], h)
    info.distortion_model, info.d = distortion[0], list(distortion[1])
    pose = PoseStamped(pose=matrix_to_pose(CAMERA))
    pose.header.frame_id = "world"
    return rgb_msg, depth_msg, info, pose


@pytest.mark.parametrize("width, height", [(848, 480), (1280, 720)])
def test_segments_driver_resolutions(width, height):
    rgb, depth, gt, K = render(BOXES, CAMERA, width=width, height=height)
    depth = add_noise(depth, np.random.default_rng(0))
    frame, overlay = segment_messages(*messages(rgb, depth, K))
    labels = image_to_numpy(frame.labels)
    assert labels.shape == (height, width) and (overlay.width, overlay.height) == (width, height)
    assert segmentation_metrics(labels, gt)["overlap_f"] > 0.9


@pytest.mark.parametrize("colour", ["bgra8", "rgba8", "bgr8"])
def test_four_channel_and_bgr_colour_is_converted(colour):
    rgb, depth, _, K = render(BOXES, CAMERA, width=160, height=120)
    frame = decode_camera_frame(*messages(rgb, depth, K, colour))
    assert np.array_equal(frame.rgb, rgb)


def distort_frame(rgb, depth_m, K, D):
    """What a camera with lens distortion D would see: each distorted pixel samples the pinhole image
    where its undistorted ray lands."""
    h, w = depth_m.shape
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    pixels = np.stack([u.ravel(), v.ravel()], 1)[:, None, :]
    ideal = cv2.undistortPoints(pixels, K, np.asarray(D), P=K).reshape(h, w, 2).astype(np.float32)
    rgb_d = cv2.remap(rgb, ideal[..., 0], ideal[..., 1], cv2.INTER_LINEAR)
    depth_d = cv2.remap(depth_m, ideal[..., 0], ideal[..., 1], cv2.INTER_NEAREST)
    return rgb_d, depth_d


def test_distorted_frame_is_undistorted_before_segmenting():
    rgb, depth, gt, K = render(BOXES, CAMERA)
    rgb_d, depth_d = distort_frame(rgb, depth, K, PLUMB_BOB)
    assert np.mean(np.abs(depth_d - depth) > 0.01) > 0.02  # the distortion moves depth edges
    msgs = messages(rgb_d, depth_d, K, distortion=("plumb_bob", PLUMB_BOB))
    decoded = decode_camera_frame(*msgs)
    inner = (slice(40, -40), slice(40, -40))
    agree = np.abs(decoded.depth_m[inner] - np.round(depth[inner] * 1000) / 1000) < 0.005
    assert agree.mean() > 0.98
    frame, _ = segment_messages(*msgs)
    assert segmentation_metrics(image_to_numpy(frame.labels), gt)["overlap_f"] > 0.9
    assert not any(frame.camera_info.d)  # the published images are undistorted


def test_unknown_distortion_model_is_refused():
    rgb, depth, _, K = render(BOXES, CAMERA, width=160, height=120)
    with pytest.raises(FrameError, match="distortion model 'fisheye62' is not supported"):
        decode_camera_frame(*messages(rgb, depth, K, distortion=("fisheye62", [0.1, 0.0, 0.0, 0.0, 0.0, 0.0])))


def test_frame_without_pose_segments_with_the_estimated_pose():
    rgb, depth, gt, K = render(BOXES, CAMERA)
    rgb_msg, depth_msg, info, _ = messages(rgb, add_noise(depth, np.random.default_rng(3)), K)
    decoded = decode_camera_frame(rgb_msg, depth_msg, info)
    assert decoded.T_world_camera is None
    decoded.T_world_camera = estimate_camera_pose(decoded.depth_m, decoded.K).T_world_camera
    pose = PoseStamped(pose=matrix_to_pose(decoded.T_world_camera))
    frame, _ = segment_frame(decoded, depth_msg, info, pose)
    assert segmentation_metrics(image_to_numpy(frame.labels), gt)["overlap_f"] > 0.9


def test_a_close_up_that_sees_less_table_than_the_area_threshold_finds_its_objects():
    # a desk close-up (0.35 m above it, fx 1067 px at 640x480): the view covers under 0.05 m^2 of the desk
    K = np.array([[1067.0, 0.0, 319.5], [0.0, 1067.0, 239.5], [0.0, 0.0, 1.0]])
    camera = look_at((-0.12, 0.0, 0.35), (0.0, 0.0, 0.0))
    boxes = [Box((-0.03, -0.04, 0.02), (0.02, 0.015, 0.02)), Box((0.03, 0.03, 0.025), (0.015, 0.02, 0.025), 0.4)]
    rgb, depth, gt, _ = render(boxes, camera, K=K)
    depth = add_noise(depth, np.random.default_rng(5))
    T = estimate_camera_pose(depth, K).T_world_camera
    result = segment_detailed(rgb, depth, K, T)
    assert result.empty_reason == "" and len(result.levels) == 1 and result.levels[0].area_m2 < 0.05
    assert segmentation_metrics(result.labels, gt)["overlap_f"] > 0.85


def test_frames_far_larger_than_the_reference_size_are_segmented_subsampled_to_it():
    assert reference_factor((480, 640), 640 * 480) == 1 and reference_factor((480, 848), 640 * 480) == 1
    assert reference_factor((720, 1280), 640 * 480) == 2 and reference_factor((1080, 1920), 640 * 480) == 3
    assert reference_factor((240, 320), 640 * 480) == 1
    rgb, depth, gt, K = render(BOXES, CAMERA, width=1280, height=960)
    exclude = np.zeros(depth.shape, bool)
    exclude[gt == 3] = True  # the robot's arm over the third box: never an object
    result = segment_detailed(rgb, add_noise(depth, np.random.default_rng(1)), K, CAMERA, exclude=exclude)
    assert result.labels.shape == depth.shape and result.table_mask.shape == depth.shape
    assert not result.labels[exclude].any() and len(np.unique(result.labels[result.labels > 0])) == 2
    assert segmentation_metrics(result.labels, np.where(exclude, 0, gt))["overlap_f"] > 0.9
