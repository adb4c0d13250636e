import numpy as np
import pytest
from seg_fixtures import Box, add_noise, look_at, render

from arm_core.frames import FrameInputError
from arm_segmentation.baseline import segment_baseline
from arm_segmentation.clustering import ClusterParams
from arm_segmentation.metrics import segmentation_metrics
from arm_segmentation.segmentation import SegmentationParams, segment, segment_detailed

CAMERA = look_at((-0.45, 0.1, 0.6), (0.05, 0.0, 0.0))


def touching_and_stacked():
    return [
        Box((0.0, -0.05, 0.04), (0.04, 0.05, 0.04), 0.0, (200, 40, 40)),
        Box((0.0, 0.05, 0.04), (0.04, 0.05, 0.04), 0.0, (40, 170, 60)),  # flush against the red box
        Box((0.0, -0.05, 0.11), (0.03, 0.03, 0.03), 0.4, (40, 60, 200)),  # stacked on the red box
        Box((0.15, 0.12, 0.06), (0.03, 0.03, 0.06), 0.3, (210, 200, 40)),
    ]


def test_separates_touching_and_stacked_objects_under_noise():
    rgb, depth, gt, K = render(touching_and_stacked(), CAMERA)
    noisy = add_noise(depth, np.random.default_rng(0))
    labels = segment(rgb, noisy, K, CAMERA)
    assert labels.dtype == np.uint16 and labels.shape == depth.shape
    m = segmentation_metrics(labels, gt)
    assert m["n_pred"] == 4
    assert m["overlap_f"] > 0.9 and m["boundary_f"] > 0.85 and m["f_at_75"] == 1.0
    baseline = segmentation_metrics(segment_baseline(rgb, noisy, K, CAMERA), gt)
    assert m["overlap_f"] > baseline["overlap_f"] + 0.1  # Euclidean clustering merges touching boxes


def test_geometry_alone_splits_a_stack_at_the_concave_crease():
    boxes = [
        Box((0.0, 0.0, 0.04), (0.05, 0.05, 0.04), 0.0, (150, 150, 150)),
        Box((0.0, 0.0, 0.11), (0.03, 0.03, 0.03), 0.5, (150, 150, 150)),
    ]
    rgb, depth, gt, K = render(boxes, CAMERA)
    params = SegmentationParams(working_stride=1, cluster=ClusterParams(use_colour=False))
    labels = segment(rgb, depth, K, CAMERA, params)
    m = segmentation_metrics(labels, gt)
    assert m["f_at_75"] == 1.0 and m["overlap_f"] > 0.85, "each box is one instance"
    # the crease band (ClusterParams.crease_reach) may cut off a sliver of the lower box's top face
    # where it is narrower than the band behind the upper box
    sizes = np.sort(np.bincount(labels.ravel())[1:])[::-1]
    assert m["n_pred"] <= 3 and sizes[2:].sum() < 0.02 * sizes.sum()


def test_finds_objects_on_two_table_levels():
    boxes = [
        Box((-0.1, 0.0, 0.05), (0.04, 0.04, 0.05), 0.2, (200, 40, 40)),
        Box((0.25, 0.0, 0.24), (0.04, 0.04, 0.04), 0.0, (40, 60, 200)),  # on the raised level at 0.2 m
    ]
    camera = look_at((-0.6, 0.0, 0.8), (0.1, 0.0, 0.0))
    shelf = Box((0.3, 0.0, 0.1), (0.2, 0.25, 0.1))  # a 0.4 x 0.5 m raised level, top at z = 0.2
    rgb, depth, gt, K = render(boxes, camera, supports=[shelf])
    result = segment_detailed(rgb, add_noise(depth, np.random.default_rng(1)), K, camera)
    heights = sorted(round(level.height_m, 2) for level in result.levels)
    assert 0.0 in heights and 0.2 in heights
    m = segmentation_metrics(result.labels, gt)
    assert m["n_pred"] == 2 and m["overlap_f"] > 0.9


def test_empty_table_gives_no_instances_and_says_why():
    rgb, depth, gt, K = render([], CAMERA)
    result = segment_detailed(rgb, add_noise(depth, np.random.default_rng(2)), K, CAMERA)
    assert result.labels.max() == 0
    assert result.empty_reason.startswith("nothing stands on the support")


def test_a_pose_without_a_table_under_it_says_so():
    rgb, depth, gt, K = render(touching_and_stacked(), CAMERA)
    upside_down = CAMERA.copy()
    upside_down[:3, :3] = np.diag([1.0, -1.0, -1.0]) @ CAMERA[:3, :3]  # world z points down
    result = segment_detailed(rgb, depth, K, upside_down)
    assert result.labels.max() == 0 and result.empty_reason.startswith("no support")
    assert segment_detailed(rgb, depth, K, CAMERA).empty_reason == ""


def test_perfectly_flat_table_seen_from_above():
    camera = look_at((0.0, 0.0, 0.8), (0.0, 0.0, 0.0), up=(1.0, 0.0, 0.0))
    rgb, depth, gt, K = render([Box((0.0, 0.0, 0.03), (0.03, 0.03, 0.03))], camera)
    for stride in (1, 2):
        result = segment_detailed(rgb, depth, K, camera, SegmentationParams(working_stride=stride))
        assert len(result.levels) == 1 and abs(result.levels[0].height_m) < 2e-3
        assert segmentation_metrics(result.labels, gt)["overlap_f"] > 0.9
    rgb, depth, gt, K = render([], camera)
    assert segment(rgb, depth, K, camera).max() == 0


def test_bad_depth_values_do_not_crash():
    rgb, depth, gt, K = render(touching_and_stacked(), CAMERA)
    bad = depth.copy()
    bad[::7, ::5] = np.nan
    bad[3::11, ::3] = np.inf
    bad[5::13, 1::4] = -1.0
    labels = segment(rgb, bad, K, CAMERA)
    assert segmentation_metrics(labels, gt)["overlap_f"] > 0.85
    assert segment(rgb, np.zeros_like(depth), K, CAMERA).max() == 0
    assert segment(rgb, np.full_like(depth, np.nan), K, CAMERA).max() == 0


@pytest.mark.parametrize(
    "change",
    ["zero_K", "nan_K", "mismatched_rgb", "grey_rgb", "nan_pose", "bad_rotation", "tiny"],
)
def test_invalid_frames_raise_input_error(change):
    rgb, depth, gt, K = render([], CAMERA, width=64, height=48)
    T = CAMERA.copy()
    if change == "zero_K":
        K = np.zeros((3, 3))
    elif change == "nan_K":
        K = K.copy()
        K[0, 0] = np.nan
    elif change == "mismatched_rgb":
        rgb = rgb[:-1]
    elif change == "grey_rgb":
        rgb = rgb[..., 0]
    elif change == "nan_pose":
        T[0, 3] = np.nan
    elif change == "bad_rotation":
        T[:3, :3] *= 2.0
    elif change == "tiny":
        depth = depth[:2, :2]
    with pytest.raises(FrameInputError):
        segment(rgb, depth, K, T)


def test_forty_objects():
    rng = np.random.default_rng(3)
    boxes = []
    for i in range(40):
        x, y = -0.25 + 0.1 * (i % 8), -0.2 + 0.1 * (i // 8)
        colour = tuple(int(c) for c in rng.integers(30, 230, 3))
        boxes.append(Box((x, y, 0.03), (0.03, 0.03, 0.03), float(rng.uniform(0, 1)), colour))
    camera = look_at((0.05, 0.0, 1.1), (0.05, 0.0, 0.0), up=(1.0, 0.0, 0.0))
    rgb, depth, gt, K = render(boxes, camera)
    m = segmentation_metrics(segment(rgb, add_noise(depth, rng), K, camera), gt)
    assert m["n_gt"] == 40 and m["n_pred"] >= 36 and m["overlap_f"] > 0.85


@pytest.mark.parametrize("seed", range(6))
def test_random_frames_never_crash(seed):
    rng = np.random.default_rng(seed)
    h, w = rng.integers(8, 120, 2)
    rgb = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    depth = rng.uniform(0, 3, (h, w)).astype(np.float32)
    depth[rng.random((h, w)) < 0.3] = 0
    if seed % 2:
        depth = np.round(depth, 1)  # large flat patches at a few heights
    eye = rng.normal(size=3)
    eye[2] = abs(eye[2]) + 0.2
    camera = look_at(eye, rng.normal(size=3) * 0.1)
    K = np.array([[w, 0, w / 2], [0, w, h / 2], [0, 0, 1.0]])
    for stride in (1, 2, 3):
        labels = segment(rgb, depth, K, camera, SegmentationParams(working_stride=stride))
        assert labels.shape == (h, w) and labels.dtype == np.uint16
    assert segment_baseline(rgb, depth, K, camera).shape == (h, w)
