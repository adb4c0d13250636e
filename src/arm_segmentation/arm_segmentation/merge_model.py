"""Learned fragment merging: a small classifier scores whether two touching regions are one object.

The hand-made merging rule (colour distance below a threshold, continuous contacts) joins touching
objects of similar colour and keeps apart the printed bands of one object. The classifier sees the
same region pair with more evidence: colour and brightness of both sides and how textured each is,
how they touch (continuous, across a depth jump, without depth, on one smooth surface), the boundary
network's outline probability along the contact, the regions' areas, heights above the support and
mean normals. It is trained on the training categories' scenes with oracle merging (`seg_merge_train`)
and runs in numpy (an ensemble of two-layer perceptrons, weights in checkpoints/merge.npz).

Region statistics are additive per pixel (`pixel_statistics`), so merged regions' statistics are
sums of their fragments'; heights are a minimum and a maximum.
"""

from __future__ import annotations

import pathlib
from dataclasses import dataclass

import numpy as np

from arm_segmentation.clustering import channel_mean, hue_distance, widest_disc_m
from arm_segmentation.perceptron import Perceptron, shared_perceptron

CHECKPOINT_DIR = pathlib.Path(__file__).resolve().parent / "checkpoints"
DEFAULT_CHECKPOINT = CHECKPOINT_DIR / "merge.npz"
HEIGHT_CLIP_M = (-0.05, 0.4)
FEATURE_NAMES = (
    "chroma_distance",
    "hue_distance",
    "saturation_small",
    "saturation_large",
    "texture_small",
    "texture_large",
    "brightness_difference",
    "brightness_darker",
    "normal_cosine",
    "log_area_small_m2",
    "log_area_large_m2",
    "log_size_ratio",
    "continuous_share",
    "broken_share",
    "unknown_share",
    "smooth_share",
    "log_contact_density",
    "outline_mean",
    "low_small_m",
    "low_large_m",
    "high_small_m",
    "high_large_m",
)
# columns of pixel_statistics
_CHROMA, _CHROMA_SQ, _BRIGHT, _NORMAL, _AREA = slice(0, 3), slice(3, 6), 6, slice(7, 10), 10


def pixel_statistics(chroma, rgb, normals_camera, area_m2) -> np.ndarray:
    """HxWx11 float64 per-pixel values whose region sums the features need: chromaticity (3), its
    square (3), brightness (0-1), the unit normal in the camera frame (3; 0 = none), the pixel's
    surface area (m^2; 0 where it is no object evidence)."""
    chroma = np.asarray(chroma, dtype=np.float64)
    brightness = channel_mean(np.asarray(rgb, dtype=np.float64))[..., None] / 255.0
    return np.concatenate(
        [chroma, chroma**2, brightness, np.asarray(normals_camera, np.float64), np.asarray(area_m2)[..., None]], -1
    )


def region_pair_features(pairs, counts, sums, size, low_m, high_m, contact_radius_px: int) -> np.ndarray:
    """(P, len(FEATURE_NAMES)) float32 features of region pairs.

    pairs: (P, 2) region ids; counts: (P, 5) their contacts (clustering.fragment_contacts: continuous,
    broken, unknown, smooth, summed outline probability); sums: (R, 11) region sums of
    pixel_statistics; size: (R,) pixels per region; low_m / high_m: (R,) lowest and highest height
    above the support (m). Each pair is ordered smaller region first, so the features are symmetric.
    """
    a, b = pairs[:, 0], pairs[:, 1]
    swap = (size[a] > size[b]) | ((size[a] == size[b]) & (a > b))
    small, large = np.where(swap, b, a), np.where(swap, a, b)
    n = np.maximum(size, 1.0)[:, None]
    means = sums / n
    chroma_s, chroma_l = means[small, _CHROMA], means[large, _CHROMA]
    texture = np.sqrt(np.maximum(means[:, _CHROMA_SQ] - means[:, _CHROMA] ** 2, 0.0)).sum(axis=1)
    saturation = np.linalg.norm(means[:, _CHROMA], axis=1)
    normal = means[:, _NORMAL]
    normal = normal / np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-6)
    bright_s, bright_l = means[small, _BRIGHT], means[large, _BRIGHT]
    total = np.maximum(counts[:, :3].sum(axis=1), 1.0)
    density = total / (2.0 * contact_radius_px * np.sqrt(np.maximum(size[small], 1.0)))
    low = np.clip(np.nan_to_num(low_m, nan=HEIGHT_CLIP_M[1], posinf=HEIGHT_CLIP_M[1]), *HEIGHT_CLIP_M)
    high = np.clip(np.nan_to_num(high_m, nan=HEIGHT_CLIP_M[0], neginf=HEIGHT_CLIP_M[0]), *HEIGHT_CLIP_M)
    columns = [
        np.abs(chroma_s - chroma_l).sum(axis=1),
        hue_distance(chroma_s, chroma_l),
        saturation[small],
        saturation[large],
        texture[small],
        texture[large],
        np.abs(bright_s - bright_l),
        np.minimum(bright_s, bright_l),
        (normal[small] * normal[large]).sum(axis=1),
        np.log10(sums[small, _AREA] + 1e-6),
        np.log10(sums[large, _AREA] + 1e-6),
        np.log(np.maximum(size[small], 1.0) / np.maximum(size[large], 1.0)),
        counts[:, 0] / total,
        counts[:, 1] / total,
        counts[:, 2] / total,
        counts[:, 3] / total,
        np.log(density),
        counts[:, 4] / total,
        low[small],
        low[large],
        high[small],
        high[large],
    ]
    return np.stack(columns, axis=1).astype(np.float32)


@dataclass(frozen=True)
class MergeParams:
    """enabled: merge regions by the classifier when its weights load (else by colour rule);
    threshold: probability above which two touching regions are one object; checkpoint: weights
    file ('' = the shipped one)."""

    enabled: bool = True
    threshold: float = 0.5
    checkpoint: str = ""


class MergeClassifier(Perceptron):
    """The merge perceptron over region-pair features (FEATURE_NAMES), in numpy."""

    def __init__(self, checkpoint: str | pathlib.Path = ""):
        super().__init__(checkpoint or DEFAULT_CHECKPOINT, FEATURE_NAMES, "merge classifier")


def _sums_by(index: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """(n, K) sums of the rows of values (M, K) grouped by index (M,)."""
    return np.stack([np.bincount(index, weights=values[:, k], minlength=n) for k in range(values.shape[1])], 1)


class LearnedMerge:
    """Scores the region pairs of one clustering grid for clustering's region merging.

    stats: HxWx11 pixel_statistics; height_m: HxW height above the support (m, NaN where none);
    outline: HxW outline probability of the boundary network on this grid; cluster: the grid's
    ClusterParams. start() takes the fragments, probability() the regions of each merging round
    (owner: fragment -> region).

    Two regions that could each stand as an object (reaching down to the support, with a disc of
    cluster.thick_fragment_m radius inside) and differ in colour by more than
    cluster.merge_chroma_threshold never merge: boxes standing flush, which the training scenes
    (objects dropped at random) hardly hold."""

    def __init__(self, classifier, stats, height_m, outline, cluster, threshold: float = 0.5):
        self.classifier, self.stats, self.height_m = classifier, stats, height_m
        self.outline, self.cluster, self.threshold = outline, cluster, threshold

    def start(self, labels: np.ndarray, n: int) -> None:
        flat = labels.ravel()
        self.size = np.bincount(flat, minlength=n + 1).astype(np.float64)
        columns = self.stats.reshape(-1, self.stats.shape[-1])
        labelled = flat > 0  # region pairs never include the background (0): its sums stay 0
        self.sums = _sums_by(flat[labelled], columns[labelled], n + 1)
        height = self.height_m.ravel()
        known = np.isfinite(height)
        self.low = np.full(n + 1, np.inf)
        self.high = np.full(n + 1, -np.inf)
        np.minimum.at(self.low, flat[known], height[known])
        np.maximum.at(self.high, flat[known], height[known])
        self.radius_m = widest_disc_m(labels, n, self.stats[..., _AREA])

    def _regions(self, owner: np.ndarray) -> dict:
        """The regions' pixels, statistic sums, lowest and highest height and widest disc."""
        n = len(owner)
        low, high, radius = np.full(n, np.inf), np.full(n, -np.inf), np.zeros(n)
        np.minimum.at(low, owner, self.low)
        np.maximum.at(high, owner, self.high)
        np.maximum.at(radius, owner, self.radius_m)
        size = np.bincount(owner, weights=self.size, minlength=n)
        return {"size": size, "sums": _sums_by(owner, self.sums, n), "low": low, "high": high, "radius": radius}

    def features(self, owner: np.ndarray, pairs: np.ndarray, counts: np.ndarray, regions=None) -> np.ndarray:
        r = regions or self._regions(owner)
        return region_pair_features(
            pairs, counts, r["sums"], r["size"], r["low"], r["high"], self.cluster.contact_radius_px
        )

    def standing_apart(self, regions: dict, pairs: np.ndarray, features: np.ndarray) -> np.ndarray:
        """(P,) bool: pairs of regions that could each stand as an object and differ in colour."""
        standing = (regions["low"] <= self.cluster.resting_height_m) & (
            regions["radius"] >= self.cluster.thick_fragment_m
        )
        colour = features[:, FEATURE_NAMES.index("chroma_distance")] > self.cluster.merge_chroma_threshold
        return standing[pairs[:, 0]] & standing[pairs[:, 1]] & colour

    def probability(self, owner: np.ndarray, pairs: np.ndarray, counts: np.ndarray) -> np.ndarray:
        """(P,) probability that each region pair (ids into owner's range) is one object."""
        regions = self._regions(owner)
        features = self.features(owner, pairs, counts, regions)
        probability = self.classifier.probability(features)
        return np.where(self.standing_apart(regions, pairs, features), 0.0, probability)


def shared_classifier(params: MergeParams) -> MergeClassifier | None:
    """The classifier for params (perceptron.shared_perceptron), or None when disabled or when the
    shipped weights are missing."""
    return shared_perceptron(MergeClassifier, params.enabled, params.checkpoint, DEFAULT_CHECKPOINT)
