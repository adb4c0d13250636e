import pathlib

import cv2
import numpy as np
import pytest

from arm_benchmarks.real.camera_variants import SPECKLE_RANGE_M, camera_variants, kept_instances, speckled, zoomed
from arm_core.camera import backproject_image
from arm_offline.inputs import find_intrinsics, load_camera
from arm_segmentation.camera_pose_estimate import estimate_camera_pose
from arm_segmentation.segmentation import segment_detailed


def _frame():
    K = np.array([[300.0, 0.0, 159.5], [0.0, 300.0, 119.5], [0.0, 0.0, 1.0]])
    u, v = np.meshgrid(np.arange(320), np.arange(240))
    depth = (0.8 + 0.001 * u + 0.0005 * v).astype(np.float32)
    rgb = np.stack([u % 256, v % 256, (u + v) % 256], -1).astype(np.uint8)
    labels = np.zeros((240, 320), np.uint16)
    labels[100:140, 140:180] = 1  # in the centre: stays in a zoomed view
    labels[5:25, 5:25] = 2  # in a corner: leaves it
    return rgb, depth, K, labels


def test_a_zoomed_view_sees_the_same_points_through_a_longer_lens():
    rgb, depth, K, labels = _frame()
    z_rgb, z_depth, z_K, (z_labels,) = zoomed(rgb, depth, K, [labels], 2.0)
    assert z_depth.shape == depth.shape and z_rgb.shape == rgb.shape and z_K[0, 0] == 600.0
    points, z_points = backproject_image(depth, K), backproject_image(z_depth, z_K)
    # the zoomed image's centre pixel sees the original's centre point (nearest resampling: within a pixel)
    assert np.abs(z_points[120, 160] - points[120, 160]).max() < 0.004
    assert kept_instances(labels, z_labels, 4.0) == 1  # the corner object left the view


def test_speckles_replace_a_share_of_the_returns_only():
    depth = np.full((200, 200), 0.7, np.float32)
    depth[:, :50] = 0.0
    out = speckled(depth, 0.01, np.random.default_rng(0))
    changed = out != depth
    assert not changed[:, :50].any() and 0.005 < changed[:, 50:].mean() < 0.015
    assert out[changed].min() >= SPECKLE_RANGE_M[0] and out[changed].max() <= SPECKLE_RANGE_M[1]


def test_every_variant_keeps_colour_depth_and_labels_aligned():
    rgb, depth, K, labels = _frame()
    for variant in camera_variants(rgb, depth, K, [labels], np.random.default_rng(1)):
        h, w = variant.depth_m.shape
        assert variant.rgb.shape == (h, w, 3) and variant.labels[0].shape == (h, w)
        assert abs(variant.K[0, 2] - (w - 1) / 2) < 1.0 and abs(variant.K[1, 2] - (h - 1) / 2) < 1.0


SHARED_REAL = pathlib.Path(__file__).resolve().parents[3] / ".." / "shared" / "real"


@pytest.mark.skipif(not (SHARED_REAL / "ycb_tables").is_dir(), reason="needs ../shared/real (not in a user's clone)")
def test_through_a_longer_lens_the_objects_at_the_image_edge_stand_on_the_table():
    folder = SHARED_REAL / "ycb_tables"
    camera = load_camera(find_intrinsics(folder))
    rgb = cv2.imread(str(folder / "color" / "000000.png"))[..., ::-1].copy()
    depth = cv2.imread(str(folder / "depth" / "000000.png"), cv2.IMREAD_UNCHANGED).astype(np.float32) / 1000.0
    rgb, depth, K, _ = zoomed(rgb, depth, camera.K, [], 1.7)
    result = segment_detailed(rgb, depth, K, estimate_camera_pose(depth, K).T_world_camera)
    # in view: a bottle, a cracker box at the right edge, a bowl and a brick (and a sliver of a sugar box)
    assert 4 <= len(np.unique(result.labels[result.labels > 0])) <= 5
    assert result.labels[100:200, 450:560].any(), "the cracker box at the image's right edge is an object"
