"""Real Kinect-class frames of printed boxes (OSD, in ../shared/real; skipped without it, as in a
user's clone): a box in front of another and a box standing on another come out as two objects."""

import json
import pathlib

import cv2
import numpy as np
import pytest

from arm_segmentation.camera_pose_estimate import estimate_camera_pose
from arm_segmentation.metrics import segmentation_metrics
from arm_segmentation.segmentation import segment

OSD = pathlib.Path(__file__).resolve().parents[3] / ".." / "shared" / "real" / "osd_learn"


@pytest.mark.skipif(not OSD.is_dir(), reason="needs ../shared/real (not in a user's clone)")
@pytest.mark.parametrize("frame", ["learn1", "learn3", "learn20", "learn25"])
def test_occluding_and_stacked_printed_boxes_are_two_objects(frame):
    intrinsics = json.loads((OSD / "intrinsics.json").read_text())
    K = np.array([[intrinsics["fx"], 0, intrinsics["cx"]], [0, intrinsics["fy"], intrinsics["cy"]], [0, 0, 1]])
    rgb = cv2.imread(str(OSD / "color" / f"{frame}.png"))[..., ::-1].copy()
    depth_m = cv2.imread(str(OSD / "depth" / f"{frame}.png"), cv2.IMREAD_UNCHANGED).astype(np.float32) / 1000.0
    truth = cv2.imread(str(OSD / "labels" / f"{frame}.png"), cv2.IMREAD_UNCHANGED)
    labels = segment(rgb, depth_m, K, estimate_camera_pose(depth_m, K).T_world_camera)
    metrics = segmentation_metrics(np.where(depth_m > 0, labels, 0), truth)
    assert metrics["f_at_75"] == 1.0, metrics  # each box is one instance covering >= 75 % of it
