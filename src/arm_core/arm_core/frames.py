"""The one RGB-D frame record and its validator.

A frame is what the camera saw plus where it was: rgb uint8 HxWx3 (None when absent), depth_m
float32 HxW metres along the optical axis (0 = no return), K 3x3 pixels, T_world_camera 4x4 pose of
the optical frame, labels HxW integer instance image (0 = background/table; None when unsegmented).
"""

from dataclasses import dataclass

import cv2
import numpy as np

MIN_IMAGE_SIDE_PX = 4
ROTATION_TOLERANCE = 1e-3  # max |R R^T - I| entry accepted as a rotation
SPECKLE_JUMP = 0.03  # neighbouring returns of one surface differ by less than this share of their depth
SPECKLE_SHARE = 1e-4  # surfaces of fewer pixels than this share of the image (30 at 640x480) are speckles
SPECKLE_MIN_PX = 4
_LOG_DEPTH_FLOOR_M = 0.05
_LOG_DEPTH_STEPS = 8  # code steps per SPECKLE_JUMP, so that rounding moves the jump by under 1/8 of it


class FrameInputError(ValueError):
    """The RGB-D frame cannot be interpreted: wrong shapes or dtypes, bad intrinsics or camera pose."""


@dataclass
class RgbdFrame:
    """One RGB-D frame (see the module docstring). visible_fraction: the simulator's ground-truth
    visible fraction per object (None outside the simulator)."""

    rgb: np.ndarray | None
    depth_m: np.ndarray
    K: np.ndarray
    T_world_camera: np.ndarray
    labels: np.ndarray | None = None
    world_frame_id: str = "world"
    stamp_s: float = 0.0
    visible_fraction: np.ndarray | None = None

    @property
    def instance_ids(self) -> list[int]:
        """Ascending non-zero labels."""
        if self.labels is None:
            return []
        ids = np.unique(self.labels)
        return [int(i) for i in ids[ids > 0]]


def validate_frame(depth_m, K, T_world_camera, rgb=None, labels=None) -> RgbdFrame:
    """Check and normalise one frame: depth_m becomes float32 with 0 wherever it is not finite and
    positive, K float64 3x3, T_world_camera float64 4x4; rgb (uint8 HxWx3) and labels (integer HxW)
    are checked when given. Raises FrameInputError on anything that cannot be repaired."""
    depth_m = np.asarray(depth_m, dtype=np.float32)
    if depth_m.ndim != 2 or min(depth_m.shape) < MIN_IMAGE_SIDE_PX:
        raise FrameInputError(
            f"depth must be an HxW image of at least {MIN_IMAGE_SIDE_PX}x{MIN_IMAGE_SIDE_PX} pixels, "
            f"got shape {depth_m.shape}"
        )
    if rgb is not None:
        rgb = np.asarray(rgb)
        if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[:2] != depth_m.shape:
            raise FrameInputError(f"rgb shape {rgb.shape} does not match depth shape {depth_m.shape} (HxWx3 expected)")
        if rgb.dtype != np.uint8:
            raise FrameInputError(f"rgb must be uint8, got {rgb.dtype}")
    if labels is not None:
        labels = np.asarray(labels)
        if labels.shape != depth_m.shape:
            raise FrameInputError(f"labels shape {labels.shape} differs from depth shape {depth_m.shape}")
        if not np.issubdtype(labels.dtype, np.integer):
            raise FrameInputError(f"labels must be an integer image, got {labels.dtype}")
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise FrameInputError(f"K must be a finite 3x3 pinhole matrix with fx, fy > 0, got {K.tolist()}")
    T = np.asarray(T_world_camera, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise FrameInputError("T_world_camera must be a finite 4x4 transform")
    R = T[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=ROTATION_TOLERANCE) or np.linalg.det(R) < 0.5:
        raise FrameInputError("T_world_camera rotation is not orthonormal")
    depth_m = np.where(np.isfinite(depth_m) & (depth_m > 0), depth_m, np.float32(0.0))
    return RgbdFrame(rgb, remove_speckles(depth_m), K, T, labels)


def remove_speckles(depth_m: np.ndarray) -> np.ndarray:
    """float32 HxW depth (m, 0 = no return) without speckles: returns that the surface around them
    contradicts.

    A real sensor scatters isolated wrong returns over the image (a RealSense gives single pixels
    up to 17 m away; sunlight and other cameras' projectors give more). Each would cut the surface it
    lands on as a depth edge. Returns are joined into surfaces where 4-neighbours differ by under
    SPECKLE_JUMP of their depth (OpenCV's filterSpeckles, run on log depth so that the jump is
    relative); a surface of fewer than SPECKLE_SHARE of the image's pixels (at least SPECKLE_MIN_PX)
    is a speckle when most of the pixels around it are returns of another surface, and becomes no
    return. Islands of returns among pixels without one (a dark object's last returns) stay, and so
    do thin structures: a 1 px pole is one surface along its length."""
    valid = depth_m > 0
    if not np.any(valid):
        return depth_m
    # log depth in steps of SPECKLE_JUMP / _LOG_DEPTH_STEPS (any finite float32 depth fits an int16)
    steps = cv2.log(np.maximum(depth_m, np.float32(_LOG_DEPTH_FLOOR_M)))
    steps -= np.float32(np.log(_LOG_DEPTH_FLOOR_M))
    steps *= np.float32(_LOG_DEPTH_STEPS / np.log1p(SPECKLE_JUMP))
    code = np.rint(steps).astype(np.int16)
    code[~valid] = -1  # no return, never part of a surface
    max_speckle_px = max(SPECKLE_MIN_PX, round(SPECKLE_SHARE * depth_m.size))
    cv2.filterSpeckles(code, -1, max_speckle_px, _LOG_DEPTH_STEPS)
    small = valid & (code < 0)
    if not np.any(small):
        return depth_m
    count, pieces = cv2.connectedComponents(small.astype(np.uint8), connectivity=8)
    ring_of = cv2.dilate(pieces.astype(np.float32), np.ones((3, 3), np.uint8)).astype(np.int64)
    ring = (ring_of > 0) & ~small
    ring_px = np.bincount(ring_of[ring], minlength=count)
    ring_returns = np.bincount(ring_of[ring & valid], minlength=count)
    speckle = ring_returns > 0.5 * ring_px
    speckle[0] = False
    return np.where(speckle[pieces], np.float32(0.0), depth_m)
