"""A real frame as other cameras would give the same scene, to check the segmentation on cameras
that no shared set holds.

- `zoom_1.7x`: the centre 1/1.7 of the view at the full image size, as a lens of 1.7x the focal
  length gives it (fx 618 -> 1050 px: the desk close-up that found nothing in a user's report);
- `1280x960`: twice the resolution (RealSense and Azure Kinect modes);
- `320x240`: half the resolution (a cheap camera, a downsampled stream);
- `speckles`: 0.5 % of the returns replaced by isolated wrong depths of 0.3-17 m (a RealSense in
  sunlight or beside another camera's projector; the shared household frames hold about 0.05 %).

Images are resampled with nearest neighbours for depth and labels (no depth is invented between two
surfaces) and by area or linear interpolation for colour. Each variant is compared with the frame as
given: its truth labels, resampled the same way, where the frame has them; and the instances found on
the frame as given that keep at least half of their pixels in the variant's view (the reference).
"""

from dataclasses import dataclass

import cv2
import numpy as np

from arm_core.boxes import cropped_intrinsics, resized_intrinsics

ZOOM = 1.7
SPECKLE_SHARE = 0.005
SPECKLE_RANGE_M = (0.3, 17.0)
MIN_KEPT_SHARE = 0.5  # an instance keeping this share of its pixels in the variant's view is still in it


@dataclass
class VariantFrame:
    name: str
    rgb: np.ndarray
    depth_m: np.ndarray
    K: np.ndarray
    labels: list[np.ndarray]  # label images of the frame (truth, predicted), transformed as the view


def _resized(rgb, depth_m, K, labels, size_wh: tuple[int, int]):
    """Every image resampled to size_wh (width, height); K scaled with it."""
    w, h = size_wh
    K = resized_intrinsics(K, depth_m.shape, (h, w))
    colour = cv2.INTER_AREA if w < depth_m.shape[1] else cv2.INTER_LINEAR
    nearest = [cv2.resize(image, (w, h), interpolation=cv2.INTER_NEAREST) for image in (depth_m, *labels)]
    return cv2.resize(rgb, (w, h), interpolation=colour), nearest[0], K, nearest[1:]


def zoomed(rgb, depth_m, K, labels, factor: float):
    """The view of a lens with factor x the focal length, at the same image size."""
    h, w = depth_m.shape
    ch, cw = int(round(h / factor)), int(round(w / factor))
    y0, x0 = (h - ch) // 2, (w - cw) // 2
    crop = (slice(y0, y0 + ch), slice(x0, x0 + cw))
    K_crop = cropped_intrinsics(K, crop)
    return _resized(rgb[crop], depth_m[crop], K_crop, [label[crop] for label in labels], (w, h))


def speckled(depth_m: np.ndarray, share: float, rng: np.random.Generator) -> np.ndarray:
    """depth_m with share of its returns replaced by wrong depths drawn uniformly in SPECKLE_RANGE_M."""
    hit = (depth_m > 0) & (rng.random(depth_m.shape) < share)
    out = depth_m.copy()
    out[hit] = rng.uniform(*SPECKLE_RANGE_M, size=int(hit.sum())).astype(np.float32)
    return out


def camera_variants(rgb, depth_m, K, labels: list[np.ndarray], rng: np.random.Generator) -> list[VariantFrame]:
    """The frame as each variant camera gives it (see the module docstring)."""
    h, w = depth_m.shape
    return [
        VariantFrame(f"zoom_{ZOOM:g}x", *zoomed(rgb, depth_m, K, labels, ZOOM)),
        VariantFrame(f"{2 * w}x{2 * h}", *_resized(rgb, depth_m, K, labels, (2 * w, 2 * h))),
        VariantFrame(f"{w // 2}x{h // 2}", *_resized(rgb, depth_m, K, labels, (w // 2, h // 2))),
        VariantFrame("speckles", rgb, speckled(depth_m, SPECKLE_SHARE, rng), K.copy(), list(labels)),
    ]


def kept_instances(original: np.ndarray, in_view: np.ndarray, scale_px: float) -> int:
    """How many instances of the original label image keep at least MIN_KEPT_SHARE of their pixels in
    the variant's view (in_view: those labels as the variant sees them; scale_px: variant pixels per
    original pixel)."""
    ids = np.unique(original[original > 0])
    if ids.size == 0:
        return 0
    before = np.bincount(original.ravel(), minlength=int(original.max()) + 1)[ids] * scale_px
    after = np.bincount(in_view.ravel(), minlength=int(original.max()) + 1)[ids]
    return int(np.sum(after >= MIN_KEPT_SHARE * before))
