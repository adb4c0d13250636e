import numpy as np
import pytest
from sensor_msgs.msg import CameraInfo, Image

from arm_ros.conversions import (
    ConversionError,
    K_from_camera_info,
    camera_info_from_K,
    depth_to_metres,
    image_to_numpy,
    matrix_to_pose,
    mesh_to_msg,
    msg_to_mesh,
    numpy_to_image,
    pose_to_matrix,
)
from arm_sim.core import COMMAND_NAMES, trajectory_targets


def test_images_round_trip():
    rgb = np.random.default_rng(0).integers(0, 255, (4, 5, 3), dtype=np.uint8)
    assert np.array_equal(image_to_numpy(numpy_to_image(rgb, "rgb8")), rgb)
    depth = np.random.default_rng(0).random((4, 5)).astype(np.float32)
    assert np.array_equal(depth_to_metres(numpy_to_image(depth, "32FC1")), depth)
    mm = (depth * 1000).astype(np.uint16)
    assert np.allclose(depth_to_metres(numpy_to_image(mm, "16UC1")), mm / 1000.0)


def test_malformed_images_raise_conversion_errors():
    msg = numpy_to_image(np.zeros((4, 5), np.float32), "32FC1")
    msg.data = msg.data[:10]
    with pytest.raises(ConversionError):
        image_to_numpy(msg)
    with pytest.raises(ConversionError):
        image_to_numpy(Image(encoding="yuv422", height=2, width=2, step=4, data=bytes(8)))
    with pytest.raises(ConversionError):
        K_from_camera_info(CameraInfo())
    assert np.allclose(
        K_from_camera_info(camera_info_from_K(np.array([[500, 0, 320], [0, 500, 240], [0, 0, 1.0]]), 640, 480))[0, 0],
        500,
    )


def test_poses_and_meshes_round_trip():
    rng = np.random.default_rng(1)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    T = np.eye(4)
    T[:3, :3] = q * np.sign(np.linalg.det(q))
    T[:3, 3] = rng.normal(size=3)
    assert np.allclose(pose_to_matrix(matrix_to_pose(T)), T)
    vertices, faces = rng.random((6, 3)), np.array([[0, 1, 2], [3, 4, 5]])
    v, f = msg_to_mesh(mesh_to_msg(vertices, faces))
    assert np.allclose(v, vertices) and np.array_equal(f, faces)
    bad = matrix_to_pose(T)
    bad.position.x = float("nan")
    with pytest.raises(ConversionError):
        pose_to_matrix(bad)


def test_trajectory_targets_interpolate_and_validate():
    current = np.zeros(8)
    targets = trajectory_targets(COMMAND_NAMES[:2], [0.5, 1.0], [[1.0, 2.0], [1.0, 2.0]], current, 0.1)
    assert targets.shape == (10, 8) and np.allclose(targets[4, :2], [1.0, 2.0])
    assert np.allclose(targets[1, :2], [0.4, 0.8])
    assert np.all(targets[:, 2:] == 0)
    for names, times, positions in [
        (["elbow"], [1.0], [[0.0]]),
        (COMMAND_NAMES[:1], [1.0, 0.5], [[0.0], [0.0]]),
        (COMMAND_NAMES[:1], [1.0], [[np.nan]]),
        (COMMAND_NAMES[:1], [], []),
    ]:
        with pytest.raises(ValueError):
            trajectory_targets(names, times, positions, current, 0.1)
