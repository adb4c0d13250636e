import numpy as np

from arm_bringup.plots import objects_crop, plot_camera_segmentation


def test_objects_crop_boxes_the_labels_with_a_margin_inside_the_image():
    labels = np.zeros((100, 120), dtype=np.uint16)
    labels[40:50, 60:70] = 3
    labels[45, 5] = 1
    rows, cols = objects_crop(labels, margin_px=10)
    assert (rows.start, rows.stop) == (30, 60)
    assert (cols.start, cols.stop) == (0, 80)
    assert objects_crop(np.zeros((4, 4), dtype=np.uint16)) == (slice(None), slice(None))


def test_camera_segmentation_figure_is_written(tmp_path):
    rgb = np.full((60, 80, 3), 128, dtype=np.uint8)
    depth = np.full((60, 80), 0.8, dtype=np.float32)
    labels = np.zeros((60, 80), dtype=np.uint16)
    labels[10:20, 10:20], labels[30:40, 50:60] = 1, 2
    path = tmp_path / "seg.png"
    plot_camera_segmentation(path, rgb, depth, labels, True, "frame")
    assert path.stat().st_size > 0
