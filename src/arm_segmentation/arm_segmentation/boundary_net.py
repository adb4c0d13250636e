"""A small RGB-D network with two outputs: where two objects meet, and what is object.

Geometry cannot separate two objects that touch on one continuous surface, and colour cannot tell a
printed label from a different object. The network looks at colour, depth, normals and height above
the support together and predicts, per working-grid pixel, the probability that the pixel lies where
two objects meet (an outline between objects) and that it lies on an object at all.

- Outline channel: a feature of the learned merging of touching fragments (merge_model) and of the
  outline pass (outline_model).
- Object channel (BoundaryParams.fill_objects, on by default): unlabelled pixels it scores above
  fill_threshold near an instance join the nearest instance: flat bases in the table band and
  surfaces without depth, which geometry leaves out.

Without the weights (or with torch missing) the segmentation runs on its geometric and colour cues
alone. Inputs are computed on the working grid (320x240 for a 640x480 frame) by `boundary_features`.
"""

from __future__ import annotations

import pathlib
from dataclasses import dataclass

import cv2
import numpy as np

CHECKPOINT_DIR = pathlib.Path(__file__).resolve().parent / "checkpoints"
DEFAULT_CHECKPOINT = CHECKPOINT_DIR / "boundary.pt"
FEATURE_CHANNELS = 9  # rgb (3), depth, depth valid, normals (3), height above the support
HEIGHT_CLIP_M = (-0.05, 0.35)
# Torch threads for one prediction. The input is small (a crop of the working grid): between frames a
# second thread falls asleep, and waking it cost more than it saved (household frames, 2 cores:
# 79 -> 43 ms a frame with one thread). The caller's thread count is restored afterwards.
PREDICT_THREADS = 1


def boundary_features(rgb: np.ndarray, depth_m: np.ndarray, normals_camera: np.ndarray, height_m: np.ndarray):
    """(9, H, W) float32 network input from HxW(x3) working-grid images: rgb uint8, depth (m, 0 =
    none), unit normals in the camera frame (0 = none), height above the support level (m, NaN = none)."""
    rgb = np.asarray(rgb, dtype=np.float32) / 255.0 - 0.5
    depth = np.asarray(depth_m, dtype=np.float32)
    valid = (depth > 0).astype(np.float32)
    height = np.clip(np.nan_to_num(np.asarray(height_m, dtype=np.float32), nan=HEIGHT_CLIP_M[0]), *HEIGHT_CLIP_M)
    channels = [
        rgb.transpose(2, 0, 1),
        (np.clip(depth, 0.0, 3.0) - 1.0)[None],
        valid[None] - 0.5,
        np.asarray(normals_camera, dtype=np.float32).transpose(2, 0, 1),
        (height * 5.0)[None],
    ]
    return np.ascontiguousarray(np.concatenate(channels, axis=0), dtype=np.float32)


def boundary_targets(labels: np.ndarray, radius_px: int = 1) -> np.ndarray:
    """HxW bool: object pixels with a pixel of another object within radius_px (where two objects
    meet; an object's outline against the background is geometry's job, and the inside of a thin
    object stays inside)."""
    labels = np.asarray(labels)
    size = 2 * radius_px + 1
    kernel = np.ones((size, size), np.uint8)
    as_float = labels.astype(np.float32)
    high = cv2.dilate(as_float, kernel)
    low = cv2.erode(np.where(labels > 0, as_float, np.float32(np.inf)), kernel)
    return (labels > 0) & ((high != as_float) | (low != as_float))


def build_network(width: int = 8):
    """The boundary U-Net: one convolution at full working resolution on either side, double
    convolutions at 1/2, 1/4 and 1/8 (widths 2, 4 and 4 x `width`)."""
    import torch
    from torch import nn

    def conv(cin: int, cout: int) -> list:
        return [nn.Conv2d(cin, cout, 3, padding=1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True)]

    def block(cin: int, cout: int) -> nn.Sequential:
        return nn.Sequential(*conv(cin, cout), *conv(cout, cout))

    class BoundaryNet(nn.Module):
        """Encoder-decoder with skips; output logits (N, 2, H, W): object outline, object pixel."""

        def __init__(self):
            super().__init__()
            w = width
            self.stem = nn.Sequential(*conv(FEATURE_CHANNELS, w))
            self.enc1, self.enc2, self.mid = block(w, 2 * w), block(2 * w, 4 * w), block(4 * w, 4 * w)
            self.dec2, self.dec1 = block(8 * w, 2 * w), block(4 * w, w)
            self.dec0 = nn.Sequential(*conv(2 * w, w))
            self.head = nn.Conv2d(w, 2, 1)
            self.pool = nn.MaxPool2d(2)

        @staticmethod
        def _up(x, like):
            return nn.functional.interpolate(x, size=like.shape[-2:], mode="bilinear", align_corners=False)

        def forward(self, x):
            e0 = self.stem(x)
            e1 = self.enc1(self.pool(e0))
            e2 = self.enc2(self.pool(e1))
            m = self.mid(self.pool(e2))
            d2 = self.dec2(torch.cat([self._up(m, e2), e2], 1))
            d1 = self.dec1(torch.cat([self._up(d2, e1), e1], 1))
            d0 = self.dec0(torch.cat([self._up(d1, e0), e0], 1))
            return self.head(d0)

    return BoundaryNet()


@dataclass(frozen=True)
class BoundaryParams:
    """fill_objects: use the network (its weights loading) and its object channel, giving unlabelled
    pixels above fill_threshold within fill_reach_px (full resolution) of an instance to the nearest
    instance; checkpoint: weights file ('' = the shipped one)."""

    fill_objects: bool = True
    fill_threshold: float = 0.9
    fill_reach_px: int = 20
    checkpoint: str = ""

    @property
    def network_used(self) -> bool:
        return self.fill_objects


class BoundaryPredictor:
    """Loads the weights once; predict(features) -> outline and object probabilities."""

    def __init__(self, checkpoint: str | pathlib.Path = ""):
        import torch

        path = pathlib.Path(checkpoint) if checkpoint else DEFAULT_CHECKPOINT
        if not path.is_file():
            raise FileNotFoundError(f"boundary network weights not found: {path}")
        try:
            state = torch.load(path, map_location="cpu", weights_only=True)
            self.config = dict(state["config"])
            self.model = build_network(int(self.config["width"]))
            self.model.load_state_dict(state["model"])
        except Exception as error:  # a pickle, zip, key or shape error: all mean "not these weights"
            reason = (str(error).splitlines() or [""])[0][:160]
            raise ValueError(f"{path} is not boundary network weights ({type(error).__name__}: {reason})") from error
        self.model.eval()
        self.path = path

    def predict(self, features: np.ndarray) -> np.ndarray:
        """(2, H, W) float32: probability that a pixel lies where two objects meet, and that it is
        on an object."""
        import torch

        threads = torch.get_num_threads()
        torch.set_num_threads(PREDICT_THREADS)
        try:
            with torch.inference_mode():
                logits = self.model(torch.from_numpy(features)[None])
        finally:
            torch.set_num_threads(threads)
        return torch.sigmoid(logits[0]).numpy()


_PREDICTORS: dict[str, BoundaryPredictor | None] = {}


def shared_predictor(params: BoundaryParams) -> BoundaryPredictor | None:
    """The predictor for params (loaded on first use, then shared), or None when disabled, or when
    the shipped weights (or torch) are missing. A checkpoint named in params that is missing raises
    FileNotFoundError; a weights file that does not load raises ValueError."""
    if not params.network_used:
        return None
    key = params.checkpoint or str(DEFAULT_CHECKPOINT)
    if key not in _PREDICTORS:
        try:
            _PREDICTORS[key] = BoundaryPredictor(params.checkpoint)
        except (FileNotFoundError, ImportError):
            if params.checkpoint:
                raise
            _PREDICTORS[key] = None
    return _PREDICTORS[key]
