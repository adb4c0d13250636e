import numpy as np

from arm_bringup.plots import plot_camera_segmentation


def test_camera_segmentation_figure_is_written(tmp_path):
    rgb = np.full((60, 80, 3), 128, dtype=np.uint8)
    depth = np.full((60, 80), 0.8, dtype=np.float32)
    labels = np.zeros((60, 80), dtype=np.uint16)
    labels[10:20, 10:20], labels[30:40, 50:60] = 1, 2
    path = tmp_path / "seg.png"
    plot_camera_segmentation(path, rgb, depth, labels, True, "frame")
    assert path.stat().st_size > 0
