"""Lens undistortion of RGB-D frames to their own pinhole K (sensor_msgs/CameraInfo distortion models).

Colour is resampled bilinearly, depth by nearest neighbour (interpolating across a depth edge would
invent points in mid-air); pixels that map outside the source image get depth 0 and black colour.
The cv2 remap maps are cached per (model, D, K, size), so a steady camera costs one remap per image.
"""

from collections import OrderedDict

import cv2
import numpy as np

# CameraInfo.distortion_model -> accepted lengths of D (rational_polynomial with 12 or 14 is OpenCV's
# extended model with thin-prism and tilt terms, as depthai publishes it)
MODELS = {"plumb_bob": (4, 5), "rational_polynomial": (8, 12, 14), "equidistant": (4,)}


class DistortionError(ValueError):
    """A distortion model or coefficient vector that cannot be applied correctly."""


def is_distorted(model: str, D) -> bool:
    """False when the image can be used as is (all-zero D, whatever the model); raises DistortionError
    for an unknown model with non-zero coefficients or a D of the wrong length."""
    D = np.asarray(D, dtype=np.float64).ravel()
    if not np.all(np.isfinite(D)):
        raise DistortionError(f"distortion coefficients are not finite: {D.tolist()}")
    if not np.any(D):
        return False
    if model not in MODELS:
        raise DistortionError(f"distortion model '{model}' is not supported (one of {sorted(MODELS)})")
    if len(D) not in MODELS[model]:
        allowed = " or ".join(str(n) for n in MODELS[model])
        raise DistortionError(f"{model} needs {allowed} coefficients, got {len(D)}")
    return True


def undistortion_maps(model: str, D, K: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """(map_x, map_y) float32 HxW: for each pixel of the undistorted image (intrinsics K), where to
    sample the distorted one."""
    D = np.asarray(D, dtype=np.float64).ravel()
    K = np.asarray(K, dtype=np.float64)
    size = (int(width), int(height))
    if model == "equidistant":
        return cv2.fisheye.initUndistortRectifyMap(K, D, np.eye(3), K, size, cv2.CV_32FC1)
    return cv2.initUndistortRectifyMap(K, D, np.eye(3), K, size, cv2.CV_32FC1)


class Undistorter:
    """Undistorts colour and depth with maps cached for the last few camera models."""

    def __init__(self, max_cached: int = 4):
        self.max_cached = max_cached
        self._maps: OrderedDict = OrderedDict()

    def maps(self, model: str, D, K: np.ndarray, width: int, height: int):
        key = (model, tuple(np.asarray(D, dtype=np.float64).ravel()), tuple(np.asarray(K).ravel()), width, height)
        if key not in self._maps:
            self._maps[key] = undistortion_maps(model, D, K, width, height)
            while len(self._maps) > self.max_cached:
                self._maps.popitem(last=False)
        self._maps.move_to_end(key)
        return self._maps[key]

    def undistort(self, rgb: np.ndarray, depth_m: np.ndarray, model: str, D, K: np.ndarray):
        """(rgb, depth_m) resampled to the undistorted pinhole K; returned as given when D is all zero."""
        if not is_distorted(model, D):
            return rgb, depth_m
        height, width = depth_m.shape
        map_x, map_y = self.maps(model, D, K, width, height)
        rgb_out = cv2.remap(rgb, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        depth_out = cv2.remap(depth_m, map_x, map_y, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        return rgb_out, depth_out
