"""Per-frame camera pose from depth alone for a camera without a calibrated pose (no rclpy).

A full estimate (camera_pose_estimate) costs about 0.1 s per frame; a check that the last support
plane still fits costs a few milliseconds. So the last estimate is reused while the share of valid
pixels within the inlier band of its plane stays at least `agreement` times its own inlier fraction
(a camera moved or tilted by more than about the inlier band, or a new K, fails this), and at most
`max_reuse_frames` frames in a row; otherwise the pose is estimated again.
"""

from dataclasses import dataclass

import numpy as np

from arm_segmentation.camera_pose_estimate import (
    CameraPoseError,
    CameraPoseEstimate,
    CameraPoseParams,
    estimate_camera_pose,
    plane_inlier_fraction,
)


@dataclass
class TrackerStats:
    estimates: int = 0
    reuses: int = 0
    failures: int = 0
    last_error: str = ""
    last_reused: bool = False


class CameraPoseTracker:
    def __init__(self, agreement: float = 0.9, max_reuse_frames: int = 30, params: CameraPoseParams | None = None):
        self.agreement = agreement
        self.max_reuse_frames = max_reuse_frames
        self.params = params or CameraPoseParams()
        self.last: CameraPoseEstimate | None = None
        self._last_K: np.ndarray | None = None
        self._reused_in_a_row = 0
        self.stats = TrackerStats()

    def update(self, depth_m: np.ndarray, K: np.ndarray) -> CameraPoseEstimate:
        """The pose for this frame. Raises CameraPoseError (and forgets the last estimate) when the
        frame has no usable support plane."""
        if self._still_fits(depth_m, K):
            self._reused_in_a_row += 1
            self.stats.reuses += 1
            self.stats.last_reused = True
            return self.last
        self.last, self._reused_in_a_row, self.stats.last_reused = None, 0, False
        try:
            estimate = estimate_camera_pose(depth_m, K, params=self.params)
        except CameraPoseError as error:
            self.stats.failures += 1
            self.stats.last_error = str(error)
            raise
        self.last, self._last_K = estimate, np.array(K, dtype=np.float64)
        self.stats.estimates += 1
        self.stats.last_error = ""
        return estimate

    def _still_fits(self, depth_m: np.ndarray, K: np.ndarray) -> bool:
        if self.last is None or self._reused_in_a_row >= self.max_reuse_frames:
            return False
        if self._last_K.shape != np.shape(K) or not np.allclose(self._last_K, K):
            return False
        fraction = plane_inlier_fraction(depth_m, K, self.last.plane_camera, params=self.params)
        return fraction >= self.agreement * self.last.inlier_fraction
