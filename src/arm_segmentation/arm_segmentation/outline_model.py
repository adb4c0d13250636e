"""Learned outline pass: every pixel within a couple of pixels of an instance's outline is decided
anew by a small classifier, object (the nearest instance's) or not.

The colour rule of boundary.refine_borders compares a pixel with the colour just inside and just
outside the outline. Real and realistic outlines need more than that: depth sits about a pixel off
the colour image and loses returns along edges, anti-aliased and shadowed edge pixels lie between
the two colours, and printed objects have colour edges inside them. The classifier sees the pixel's
colour and that of both sides, their depths (and which have none), the signed distance to the
outline, the local colour gradient, how much of the neighbourhood the instances cover and the
boundary network's object probability. It is trained on the training categories' scenes against
the true masks (`seg_outline_train`) and runs in numpy (weights in checkpoints/outline.npz).
"""

from __future__ import annotations

import pathlib
from dataclasses import dataclass

import cv2
import numpy as np

from arm_core.boxes import mask_box
from arm_core.vectors import channel_sum
from arm_segmentation.boundary import OutlineBand, outline_band
from arm_segmentation.clustering import channel_mean
from arm_segmentation.perceptron import Perceptron, shared_perceptron

CHECKPOINT_DIR = pathlib.Path(__file__).resolve().parent / "checkpoints"
DEFAULT_CHECKPOINT = CHECKPOINT_DIR / "outline.npz"
DEPTH_CLIP_M = 0.05
FEATURE_NAMES = (
    "red",
    "green",
    "blue",
    "inside_red",
    "inside_green",
    "inside_blue",
    "outside_red",
    "outside_green",
    "outside_blue",
    "to_inside",
    "to_outside",
    "blurred_to_inside",
    "blurred_to_outside",
    "signed_distance_px",
    "has_depth",
    "inside_has_depth",
    "outside_has_depth",
    "depth_minus_inside",
    "depth_minus_outside",
    "inside_minus_outside",
    "gradient",
    "covered_share",
    "objectness",
)


@dataclass(frozen=True)
class OutlineParams:
    """enabled: run the pass when its weights load and the boundary network's object map exists;
    band_px: full-resolution pixels this near an outline are decided; blur_px: box filter of the
    inside and outside colour samples; threshold: object probability above which a pixel is the
    instance's; iterations: passes (each around the outline the previous one left); checkpoint:
    weights file ('' = the shipped one)."""

    enabled: bool = True
    band_px: int = 2
    blur_px: int = 3
    threshold: float = 0.5
    iterations: int = 2
    checkpoint: str = ""


@dataclass
class OutlineImage:
    """What the features read from one frame (or crop), computed once for all passes: rgb (HxWx3
    uint8), colour (HxWx3 float32 in 0-1, box-blurred by blur_px), gradient (HxW float32, Sobel
    magnitude of the lightly smoothed grey image), depth_m (HxW float32 metres, 0 = no return),
    objectness (HxW float32, the boundary network's object probability at full resolution)."""

    rgb: np.ndarray
    colour: np.ndarray
    gradient: np.ndarray
    depth_m: np.ndarray
    objectness: np.ndarray


def outline_image(rgb, depth_m, objectness, blur_px: int) -> OutlineImage:
    colour = np.asarray(cv2.blur(rgb, (blur_px, blur_px)) if blur_px > 1 else rgb, np.float32) / 255.0
    grey = cv2.GaussianBlur(channel_mean(np.asarray(rgb, np.float32)) / 255.0, (3, 3), 0)
    gradient = np.hypot(cv2.Sobel(grey, cv2.CV_32F, 1, 0), cv2.Sobel(grey, cv2.CV_32F, 0, 1))
    depth = np.asarray(depth_m, np.float32)
    return OutlineImage(np.asarray(rgb), colour, gradient, depth, np.asarray(objectness, np.float32))


def outline_features(labels: np.ndarray, image: OutlineImage, band: OutlineBand) -> np.ndarray:
    """(P, len(FEATURE_NAMES)) float32 features of the band's pixels of the HxW instance labels."""
    r, c = band.rows, band.cols
    ir, ic, orow, ocol = band.inside_rows, band.inside_cols, band.outside_rows, band.outside_cols
    pixel = np.asarray(image.rgb[r, c], np.float32) / 255.0
    inside, outside, blurred = image.colour[ir, ic], image.colour[orow, ocol], image.colour[r, c]
    covered = (labels > 0).astype(np.uint8)
    signed = (
        cv2.distanceTransform(covered, cv2.DIST_L2, 3)[r, c] - cv2.distanceTransform(1 - covered, cv2.DIST_L2, 3)[r, c]
    )
    d, d_in, d_out = image.depth_m[r, c], image.depth_m[ir, ic], image.depth_m[orow, ocol]
    has, has_in, has_out = d > 0, d_in > 0, d_out > 0

    def depth_step(a, b, known):
        return np.where(known, np.clip(a - b, -DEPTH_CLIP_M, DEPTH_CLIP_M) / DEPTH_CLIP_M, 0.0)

    share = cv2.blur(covered.astype(np.float32), (5, 5))[r, c]
    columns = [
        pixel,
        inside,
        outside,
        channel_sum(np.abs(pixel - inside)),
        channel_sum(np.abs(pixel - outside)),
        channel_sum(np.abs(blurred - inside)),
        channel_sum(np.abs(blurred - outside)),
        signed,
        has,
        has_in,
        has_out,
        depth_step(d, d_in, has & has_in),
        depth_step(d, d_out, has & has_out),
        depth_step(d_in, d_out, has_in & has_out),
        image.gradient[r, c],
        share,
        image.objectness[r, c],
    ]
    return np.concatenate([np.asarray(x, np.float32).reshape(len(r), -1) for x in columns], axis=1)


class OutlineClassifier(Perceptron):
    """The outline perceptron over band-pixel features (FEATURE_NAMES), in numpy."""

    def __init__(self, checkpoint: str | pathlib.Path = ""):
        super().__init__(checkpoint or DEFAULT_CHECKPOINT, FEATURE_NAMES, "outline classifier")


def refine_outline(labels, rgb, depth_m, objectness, classifier: OutlineClassifier, params: OutlineParams):
    """uint16 labels with the pixels near the instances' outlines given to the nearest instance
    where the classifier says they are its object, and to the background elsewhere."""
    box = mask_box(labels, 4 * params.band_px + 4)
    if box is None:
        return labels
    crop = labels[box]
    image = outline_image(rgb[box], depth_m[box], objectness[box], params.blur_px)
    for _ in range(params.iterations):
        band = outline_band(crop, params.band_px)
        if band is None:
            break
        features = outline_features(crop, image, band)
        is_object = classifier.probability(features) > params.threshold
        crop = crop.copy()
        crop[band.rows, band.cols] = np.where(is_object, band.candidate, 0)
    out = labels.copy()
    out[box] = crop
    return out


def shared_outline_classifier(params: OutlineParams) -> OutlineClassifier | None:
    """The classifier for params (perceptron.shared_perceptron), or None when disabled or when the
    shipped weights are missing."""
    return shared_perceptron(OutlineClassifier, params.enabled, params.checkpoint, DEFAULT_CHECKPOINT)
