"""Real camera frames (in ../shared/real; skipped without it, as in a user's clone): in OSD's
Kinect-class frames of printed boxes, a box in front of another and a box standing on another come
out as two objects; in RealSense frames of household objects, a jug's handle and a drill's chuck,
which stand off their objects, are parts of them."""

import json
import pathlib

import cv2
import numpy as np
import pytest

from arm_segmentation.camera_pose_estimate import estimate_camera_pose
from arm_segmentation.metrics import segmentation_metrics
from arm_segmentation.segmentation import segment

REAL = pathlib.Path(__file__).resolve().parents[3] / ".." / "shared" / "real"
OSD = REAL / "osd_learn"
HOUSEHOLD = REAL / "ycb_tables"


def load(folder: pathlib.Path, frame: str):
    """(rgb, depth m, K) of a frame in the reconstruct_frames layout (depth in mm)."""
    intrinsics = json.loads((folder / "intrinsics.json").read_text())
    K = np.array([[intrinsics["fx"], 0, intrinsics["cx"]], [0, intrinsics["fy"], intrinsics["cy"]], [0, 0, 1]])
    rgb = cv2.imread(str(folder / "color" / f"{frame}.png"))[..., ::-1].copy()
    depth_m = cv2.imread(str(folder / "depth" / f"{frame}.png"), cv2.IMREAD_UNCHANGED).astype(np.float32) / 1000.0
    return rgb, depth_m, K


@pytest.mark.skipif(not OSD.is_dir(), reason="needs ../shared/real (not in a user's clone)")
@pytest.mark.parametrize("frame", ["learn1", "learn3", "learn20", "learn25"])
def test_occluding_and_stacked_printed_boxes_are_two_objects(frame):
    rgb, depth_m, K = load(OSD, frame)
    truth = cv2.imread(str(OSD / "labels" / f"{frame}.png"), cv2.IMREAD_UNCHANGED)
    labels = segment(rgb, depth_m, K, estimate_camera_pose(depth_m, K).T_world_camera)
    metrics = segmentation_metrics(np.where(depth_m > 0, labels, 0), truth)
    assert metrics["f_at_75"] == 1.0, metrics  # each box is one instance covering >= 75 % of it


@pytest.mark.skipif(not HOUSEHOLD.is_dir(), reason="needs ../shared/real (not in a user's clone)")
@pytest.mark.parametrize(
    "frame, body_px, part_px",
    [("000002", (218, 173), (294, 153)), ("000003", (436, 230), (493, 229))],  # (column, row)
    ids=["jug_and_its_handle", "drill_and_its_chuck"],
)
def test_a_part_standing_off_its_object_is_that_object(frame, body_px, part_px):
    rgb, depth_m, K = load(HOUSEHOLD, frame)
    labels = segment(rgb, depth_m, K, estimate_camera_pose(depth_m, K).T_world_camera)
    body, part = labels[body_px[1], body_px[0]], labels[part_px[1], part_px[0]]
    assert body > 0 and part == body
