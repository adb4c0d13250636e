"""Colour images of any common driver encoding -> rgb8 (Azure Kinect publishes bgra8, RealSense
rgb8, OAK-D bgr8): arm_ros.conversions decodes rgb8 and bgr8 only."""

import numpy as np
from sensor_msgs.msg import Image

from arm_ros.conversions import ConversionError
from arm_ros.conversions.images import image_to_numpy, numpy_to_image

# encoding -> channel indices of R, G, B in the pixel
COLOUR_ENCODINGS = {"rgb8": (0, 1, 2), "bgr8": (2, 1, 0), "rgba8": (0, 1, 2), "bgra8": (2, 1, 0)}


def colour_to_rgb(msg: Image) -> np.ndarray:
    """Image in rgb8, bgr8, rgba8 or bgra8 -> HxWx3 uint8 RGB (a copy). Raises ConversionError."""
    if msg.encoding not in COLOUR_ENCODINGS:
        expected = tuple(COLOUR_ENCODINGS)
        raise ConversionError(f"rgb encoding '{msg.encoding}' not supported (expected one of {expected})")
    channels = 4 if msg.encoding.endswith("a8") else 3
    # read the rows as mono8 bytes (image_to_numpy checks sizes and step), then split the channels
    flat = Image(header=msg.header, height=msg.height, width=msg.width * channels, encoding="mono8")
    flat.is_bigendian, flat.step, flat.data = msg.is_bigendian, msg.step, msg.data
    pixels = image_to_numpy(flat).reshape(int(msg.height), int(msg.width), channels)
    return np.ascontiguousarray(pixels[..., list(COLOUR_ENCODINGS[msg.encoding])])


def as_rgb8_msg(msg: Image) -> Image:
    """rgb8 and bgr8 messages as they are; rgba8 and bgra8 converted to rgb8 (same header)."""
    if msg.encoding in ("rgb8", "bgr8"):
        return msg
    return numpy_to_image(colour_to_rgb(msg), "rgb8", msg.header)
