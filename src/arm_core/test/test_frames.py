import numpy as np
import pytest

from arm_core.camera import intrinsics, look_at
from arm_core.frames import FrameInputError, validate_frame

K = intrinsics(32, 24)
T = look_at((0.5, 0.0, 0.5), (0.0, 0.0, 0.0))


def _inputs():
    depth = np.full((24, 32), 1.0, np.float32)
    return depth, np.zeros((24, 32, 3), np.uint8), np.zeros((24, 32), np.uint16)


def test_valid_frame_is_normalised():
    depth, rgb, labels = _inputs()
    depth[0, :3] = (np.nan, -1.0, np.inf)
    labels[5, 5] = 2
    frame = validate_frame(depth.astype(np.float64), K, T, rgb=rgb, labels=labels)
    assert frame.depth_m.dtype == np.float32 and np.all(frame.depth_m[0, :3] == 0) and frame.depth_m[1, 1] == 1
    assert frame.K.dtype == np.float64 and frame.T_world_camera.dtype == np.float64
    assert frame.instance_ids == [2]


@pytest.mark.parametrize(
    "change, message",
    [
        ("tiny_depth", "at least 4x4"),
        ("rgb_shape", "rgb shape"),
        ("rgb_dtype", "uint8"),
        ("labels_shape", "labels shape"),
        ("labels_dtype", "integer"),
        ("nan_K", "pinhole"),
        ("nan_pose", "finite 4x4"),
        ("scaled_rotation", "orthonormal"),
        ("reflection", "orthonormal"),
    ],
)
def test_bad_frames_raise_one_clear_error(change, message):
    depth, rgb, labels = _inputs()
    K_bad, T_bad = K.copy(), T.copy()
    if change == "tiny_depth":
        depth = depth[:3]
    elif change == "rgb_shape":
        rgb = rgb[:-1]
    elif change == "rgb_dtype":
        rgb = rgb.astype(np.float32)
    elif change == "labels_shape":
        labels = labels[:, :-1]
    elif change == "labels_dtype":
        labels = labels.astype(np.float32)
    elif change == "nan_K":
        K_bad[0, 0] = np.nan
    elif change == "nan_pose":
        T_bad[0, 3] = np.nan
    elif change == "scaled_rotation":
        T_bad[:3, :3] *= 1.01
    elif change == "reflection":
        T_bad[:3, 0] *= -1
    with pytest.raises(FrameInputError, match=message) as error:
        validate_frame(depth, K_bad, T_bad, rgb=rgb, labels=labels)
    assert isinstance(error.value, ValueError)


def test_speckles_become_no_return_and_surfaces_stay():
    depth = np.full((120, 160), 0.8, np.float32)
    depth[50, 50] = 15.0  # a lone wrong return far behind
    depth[60, 60:62] = 0.4  # two in front
    depth[10:110, 100] = 0.5  # a 1 px pole in front of the table
    depth[80:90, 10:20] = 3.0  # a far surface of 100 px
    depth[20:30, 20:30] = 0.0  # no return stays no return
    depth[:, 130:] = np.linspace(0.8, 2.4, 120, dtype=np.float32)[:, None]  # a slope, 1.3 % a row
    depth[95:115, 30:60] = 0.0  # a dark object that returned almost nothing ...
    depth[104:106, 44:46] = 0.55  # ... but these four returns, which stay
    frame = validate_frame(depth, intrinsics(160, 120), T)
    assert frame.depth_m[50, 50] == 0 and not frame.depth_m[60, 60:62].any()
    changed = frame.depth_m != depth
    assert changed.sum() == 3
    assert validate_frame(frame.depth_m, intrinsics(160, 120), T).depth_m.tolist() == frame.depth_m.tolist()
