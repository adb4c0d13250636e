import numpy as np
import pytest
from std_msgs.msg import Header

from arm_ros.conversions import ConversionError
from arm_ros.conversions.clouds import labelled_cloud_msg, labelled_cloud_to_numpy


def test_labelled_cloud_round_trip_and_pcl_packed_colour():
    rng = np.random.default_rng(0)
    points = rng.uniform(-1, 1, (50, 3)).astype(np.float32)
    colours = rng.integers(0, 256, (50, 3)).astype(np.uint8)
    labels = rng.integers(1, 5, 50)
    msg = labelled_cloud_msg(points, colours, labels, Header(frame_id="camera_color_optical_frame"))
    assert (msg.width, msg.height, msg.point_step, msg.row_step) == (50, 1, 20, 1000)
    assert [f.name for f in msg.fields] == ["x", "y", "z", "rgb", "label"]
    packed = np.frombuffer(bytes(msg.data), dtype="<u4").reshape(50, 5)[:, 3]
    assert packed[0] == (int(colours[0, 0]) << 16) | (int(colours[0, 1]) << 8) | int(colours[0, 2])
    back_points, back_colours, back_labels = labelled_cloud_to_numpy(msg)
    assert np.array_equal(back_points, points) and np.array_equal(back_colours, colours)
    assert np.array_equal(back_labels, labels)


def test_other_layouts_are_refused():
    msg = labelled_cloud_msg(np.zeros((3, 3)), np.zeros((3, 3)), np.ones(3), Header())
    msg.fields = msg.fields[:3]
    with pytest.raises(ConversionError, match="not a labelled cloud"):
        labelled_cloud_to_numpy(msg)
    empty = labelled_cloud_msg(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), Header())
    assert labelled_cloud_to_numpy(empty)[0].shape == (0, 3)
