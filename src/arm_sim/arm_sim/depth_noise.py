"""Depth-sensor noise model (structured-light / stereo RGB-D camera).

Axial noise grows with distance squared, depth is quantised in disparity, and returns drop out
at depth edges, at grazing angles, beyond the working range and at random.
"""

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass
class DepthNoise:
    enabled: bool = True
    axial_sigma_m: float = 0.0012  # sigma(z) = axial_sigma_m + axial_quadratic * (z - 0.4)^2
    axial_quadratic: float = 0.0019
    baseline_m: float = 0.075  # stereo baseline for disparity quantisation
    subpixel: float = 1.0 / 8.0  # disparity quantisation step, pixels
    edge_jump_m: float = 0.03  # a neighbour this much nearer or farther marks a depth edge
    edge_dropout: float = 0.5
    grazing_deg: float = 78.0  # surfaces seen more obliquely than this lose their returns
    random_dropout: float = 0.003
    min_range_m: float = 0.1
    max_range_m: float = 3.0


_RAY_CACHE: dict = {}


def _unit_rays(K: np.ndarray, shape: tuple) -> np.ndarray:
    key = (shape, tuple(np.round(np.asarray(K).ravel(), 6)))
    if key not in _RAY_CACHE:
        h, w = shape
        u, v = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
        rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1).astype(np.float32)
        _RAY_CACHE.clear()
        _RAY_CACHE[key] = rays
    return _RAY_CACHE[key]


def _surface_obliquity_cos(depth_m: np.ndarray, K: np.ndarray) -> np.ndarray:
    """|cos| of the angle between each pixel's viewing ray and the surface normal."""
    rays = _unit_rays(K, depth_m.shape)
    points = rays * depth_m[..., None]
    du = cv2.Sobel(points, cv2.CV_32F, 1, 0, ksize=1)
    dv = cv2.Sobel(points, cv2.CV_32F, 0, 1, ksize=1)
    normal = np.cross(du, dv)
    dot = np.einsum("ijk,ijk->ij", normal, rays)
    norms = np.sqrt(np.einsum("ijk,ijk->ij", normal, normal) * np.einsum("ijk,ijk->ij", rays, rays)) + 1e-12
    return np.abs(dot) / norms


def apply_depth_noise(depth_m: np.ndarray, K: np.ndarray, rng: np.random.Generator, noise: DepthNoise) -> np.ndarray:
    """Noisy copy of a perfect depth image (float32 metres, 0 = no return)."""
    depth = np.asarray(depth_m, dtype=np.float32).copy()
    depth[~np.isfinite(depth)] = 0.0
    if not noise.enabled:
        return depth
    valid = (depth > noise.min_range_m) & (depth < noise.max_range_m)
    local_max = cv2.dilate(depth, np.ones((3, 3), np.uint8))
    local_min = cv2.erode(np.where(valid, depth, np.inf).astype(np.float32), np.ones((3, 3), np.uint8))
    edge = (local_max - local_min) > noise.edge_jump_m
    grazing = _surface_obliquity_cos(depth, K) < np.cos(np.deg2rad(noise.grazing_deg))
    uniform = rng.random(depth.shape, dtype=np.float32)
    drop = (edge & (uniform < noise.edge_dropout)) | grazing
    drop |= rng.random(depth.shape, dtype=np.float32) < noise.random_dropout
    sigma = noise.axial_sigma_m + noise.axial_quadratic * (depth - 0.4) ** 2
    noisy = depth + rng.standard_normal(depth.shape, dtype=np.float32) * sigma
    focal_baseline = float(K[0, 0]) * noise.baseline_m
    disparity = focal_baseline / np.maximum(noisy, 1e-3)
    noisy = focal_baseline / np.maximum(np.round(disparity / noise.subpixel) * noise.subpixel, 1e-6)
    return np.where(valid & ~drop, noisy, 0.0).astype(np.float32)


@dataclass
class SensorArtefacts:
    """What a structured-light sensor does on real scenes beyond DepthNoise: returns missing on dark
    and shiny surfaces (in blobs), mixed ("flying") pixels at depth edges, and depth registered to
    colour about a pixel off."""

    dark_dropout: float = 0.55  # share of a dark surface lost
    shiny_dropout: float = 0.25  # share of a shiny surface lost, plus its highlights
    highlight_level: float = 0.9  # colour intensity (0-1) above which a shiny surface returns nothing
    blob_px: int = 6  # size of dropout blobs
    flying_fraction: float = 0.5  # share of edge pixels that take a depth between the two sides
    edge_jump_m: float = 0.03


def _blobs(shape: tuple, blob_px: int, share: float, rng: np.random.Generator) -> np.ndarray:
    """A random mask of about `share` of the pixels, in blobs of about blob_px."""
    h, w = shape
    coarse = rng.uniform(size=(h // blob_px + 2, w // blob_px + 2)).astype(np.float32)
    smooth = cv2.resize(coarse, (w + 2 * blob_px, h + 2 * blob_px), interpolation=cv2.INTER_LINEAR)
    return smooth[blob_px : blob_px + h, blob_px : blob_px + w] < share


def apply_sensor_artefacts(
    depth_m: np.ndarray,
    rgb: np.ndarray,
    dark: np.ndarray,
    shiny: np.ndarray,
    shift_px: tuple,
    rng: np.random.Generator,
    artefacts: SensorArtefacts,
) -> np.ndarray:
    """Depth (float32 m, 0 = no return) with the artefacts of real sensors. dark / shiny: boolean
    masks of the pixels on such surfaces; shift_px: (columns, rows) misregistration."""
    depth = depth_m.copy()
    lost = dark & _blobs(depth.shape, artefacts.blob_px, artefacts.dark_dropout, rng)
    highlight = rgb.min(axis=2) > 255 * artefacts.highlight_level
    lost |= shiny & (highlight | _blobs(depth.shape, artefacts.blob_px, artefacts.shiny_dropout, rng))
    depth[lost] = 0.0
    # flying pixels: an edge pixel takes a depth between its own and its farther neighbour's
    padded = np.pad(depth, 1, mode="edge")
    neighbours = np.stack([padded[1:-1, 2:], padded[1:-1, :-2], padded[2:, 1:-1], padded[:-2, 1:-1]])
    farther = np.where(neighbours > 0, neighbours, 0.0).max(axis=0)
    edge = (depth > 0) & (farther - depth > artefacts.edge_jump_m)
    edge &= rng.uniform(size=depth.shape) < artefacts.flying_fraction
    t = rng.uniform(0.1, 0.9, size=depth.shape).astype(np.float32)
    depth = np.where(edge, depth + t * (farther - depth), depth).astype(np.float32)
    dx, dy = shift_px
    if dx or dy:
        depth = np.roll(depth, (dy, dx), axis=(0, 1))
        if dy:
            depth[(slice(0, dy) if dy > 0 else slice(dy, None)), :] = 0.0
        if dx:
            depth[:, (slice(0, dx) if dx > 0 else slice(dx, None))] = 0.0
    return depth
