"""sensor_msgs/Image (colour, depth and label encodings) and CameraInfo <-> numpy."""

import numpy as np
from sensor_msgs.msg import CameraInfo, Image

from arm_ros.conversions import ConversionError

# encoding -> (numpy dtype, channels)
IMAGE_ENCODINGS = {
    "rgb8": (np.uint8, 3),
    "bgr8": (np.uint8, 3),
    "mono8": (np.uint8, 1),
    "mono16": (np.uint16, 1),
    "16UC1": (np.uint16, 1),
    "32FC1": (np.float32, 1),
    "32SC1": (np.int32, 1),
}
RGB_ENCODINGS = ("rgb8", "bgr8")
DEPTH_ENCODINGS = ("32FC1", "16UC1", "mono16")
LABEL_ENCODINGS = ("16UC1", "mono16")


def image_to_numpy(msg: Image) -> np.ndarray:
    """Image -> HxW or HxWxC array (a copy). Raises ConversionError on malformed messages."""
    if msg.encoding not in IMAGE_ENCODINGS:
        raise ConversionError(f"unsupported image encoding '{msg.encoding}'")
    dtype, channels = IMAGE_ENCODINGS[msg.encoding]
    itemsize = np.dtype(dtype).itemsize
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    if height <= 0 or width <= 0:
        raise ConversionError(f"empty image {width}x{height}")
    row_bytes = width * channels * itemsize
    if step < row_bytes or len(msg.data) < step * height:
        raise ConversionError(
            f"image data too short: {len(msg.data)} bytes for {width}x{height} {msg.encoding} step {step}"
        )
    buffer = np.frombuffer(bytes(msg.data), dtype=np.uint8, count=step * height).reshape(height, step)
    array = buffer[:, :row_bytes].copy().view(dtype)
    if msg.is_bigendian != (np.little_endian is False) and itemsize > 1:
        array = array.byteswap()
    array = array.reshape(height, width, channels)
    if msg.encoding == "bgr8":
        array = array[..., ::-1].copy()
    return array[..., 0] if channels == 1 else array


def numpy_to_image(array: np.ndarray, encoding: str, header=None) -> Image:
    """HxW or HxWxC array -> Image with the given encoding."""
    if encoding not in IMAGE_ENCODINGS:
        raise ConversionError(f"unsupported image encoding '{encoding}'")
    dtype, channels = IMAGE_ENCODINGS[encoding]
    array = np.ascontiguousarray(array, dtype=dtype)
    if array.ndim == 2:
        array = array[..., None]
    if array.ndim != 3 or array.shape[2] != channels:
        raise ConversionError(f"array of shape {array.shape} does not fit encoding {encoding}")
    msg = Image()
    if header is not None:
        msg.header = header
    msg.height, msg.width = int(array.shape[0]), int(array.shape[1])
    msg.encoding = encoding
    msg.is_bigendian = 0
    msg.step = int(array.shape[1] * channels * array.itemsize)
    msg.data = array.tobytes()
    return msg


def rgb_to_numpy(msg: Image) -> np.ndarray:
    """rgb8/bgr8 Image -> HxWx3 uint8 in RGB order. Raises ConversionError on other encodings."""
    if msg.encoding not in RGB_ENCODINGS:
        raise ConversionError(f"rgb encoding '{msg.encoding}' not supported (expected one of {RGB_ENCODINGS})")
    return image_to_numpy(msg)


def depth_to_metres(msg: Image) -> np.ndarray:
    """Depth Image (32FC1 metres or 16UC1/mono16 millimetres) -> float32 metres, 0 = no return."""
    if msg.encoding not in DEPTH_ENCODINGS:
        raise ConversionError(f"depth encoding '{msg.encoding}' not supported (expected one of {DEPTH_ENCODINGS})")
    depth = image_to_numpy(msg)
    if msg.encoding == "32FC1":
        depth_m = depth.astype(np.float32)
    else:
        depth_m = depth.astype(np.float32) * 1e-3
    depth_m[~np.isfinite(depth_m) | (depth_m < 0)] = 0.0
    return depth_m


def labels_to_numpy(msg: Image) -> np.ndarray:
    """Instance label Image (16UC1/mono16) -> uint16 HxW. Raises ConversionError on other encodings."""
    if msg.encoding not in LABEL_ENCODINGS:
        raise ConversionError(f"labels encoding '{msg.encoding}' not supported (expected 16UC1)")
    return image_to_numpy(msg).astype(np.uint16)


def camera_info_from_K(K: np.ndarray, width: int, height: int, header=None) -> CameraInfo:
    info = CameraInfo()
    if header is not None:
        info.header = header
    info.width, info.height = int(width), int(height)
    info.distortion_model = "plumb_bob"
    info.d = [0.0] * 5
    info.k = [float(v) for v in np.asarray(K, dtype=np.float64).reshape(9)]
    info.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    P = np.zeros((3, 4))
    P[:3, :3] = np.asarray(K).reshape(3, 3)
    info.p = [float(v) for v in P.reshape(12)]
    return info


def K_from_camera_info(info: CameraInfo) -> np.ndarray:
    """CameraInfo -> 3x3 K. Raises ConversionError on zero or non-finite intrinsics."""
    K = np.array(info.k, dtype=np.float64).reshape(3, 3)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if not np.all(np.isfinite(K)) or fx <= 0 or fy <= 0 or cx <= 0 or cy <= 0:
        raise ConversionError(f"invalid intrinsics fx={fx} fy={fy} cx={cx} cy={cy}")
    return K
