import numpy as np
from seg_fixtures import Box, add_noise, look_at, render
from test_segmentation import CAMERA, touching_and_stacked

from arm_segmentation.clustering import ClusterParams, merge_fragments
from arm_segmentation.metrics import segmentation_metrics
from arm_segmentation.segmentation import FineParams, SegmentationParams, fine_crop, segment


def test_full_resolution_crop_and_working_grid_agree():
    rgb, depth, gt, K = render(touching_and_stacked(), CAMERA)
    noisy = add_noise(depth, np.random.default_rng(4))
    objects = np.zeros((240, 320), dtype=bool)
    objects[100:120, 50:90] = True
    assert fine_crop(objects, 2, (480, 640), FineParams()) == (slice(188, 252), slice(88, 192))
    assert fine_crop(objects, 2, (480, 640), FineParams(max_pixels=1000)) is None
    assert fine_crop(np.zeros_like(objects), 2, (480, 640), FineParams()) is None
    for fine in (FineParams(), FineParams(max_pixels=0)):  # crop at full resolution, then the working grid
        m = segmentation_metrics(segment(rgb, noisy, K, CAMERA, SegmentationParams(fine=fine)), gt)
        assert m["n_pred"] == 4 and m["overlap_f"] > 0.9 and m["f_at_75"] == 1.0


def test_object_nearer_than_the_minimum_range_is_found():
    camera = look_at((-0.3, 0.0, 0.14), (0.2, 0.0, 0.0))
    boxes = [
        Box((-0.2, 0.0, 0.04), (0.03, 0.08, 0.04), 0.0, (200, 60, 160)),
        Box((0.15, 0.05, 0.05), (0.03, 0.03, 0.05)),
    ]
    rgb, depth, gt, K = render(boxes, camera)
    near = gt == 1
    assert np.all(depth[near] < 0.16) and near.mean() > 0.1
    depth = np.where(near, 0.0, add_noise(depth, np.random.default_rng(5))).astype(np.float32)
    m = segmentation_metrics(segment(rgb, depth, K, camera), gt)
    assert m["n_pred"] == 2 and m["f_at_75"] == 1.0


def test_missing_background_beyond_the_table_is_no_object():
    rgb, depth, gt, K = render(touching_and_stacked(), CAMERA, floor_z=-5.0)
    far = depth > 2.0  # beyond the sensor's range: the floor far below returns nothing
    assert far.mean() > 0.05
    labels = segment(rgb, np.where(far, 0.0, depth).astype(np.float32), K, CAMERA)
    assert segmentation_metrics(labels, gt)["n_pred"] == 4


def test_region_merging_does_not_chain_small_colour_steps():
    labels = np.repeat(np.arange(1, 4), 10)[None, :].repeat(10, axis=0)  # fragments A | B | C
    chroma = np.zeros((10, 30, 3), dtype=np.float32)
    chroma[:, :10] = (0.0, 0.0, 0.0)
    chroma[:, 10:20] = (0.04, -0.04, 0.0)  # 0.08 from A
    chroma[:, 20:] = (0.11, -0.11, 0.0)  # 0.14 from B, 0.22 from A
    depth = np.full((10, 30), 0.8, dtype=np.float32)
    area = np.full((10, 30), 1e-4)
    merged = merge_fragments(labels, 3, depth, chroma, area, ClusterParams())
    assert len(np.unique(merged[:, :20])) == 1 and np.all(merged[:, 20:] != merged[0, 0])
    chained = merge_fragments(labels, 3, depth, chroma, area, ClusterParams(agglomerative=False))
    assert len(np.unique(chained)) == 1
