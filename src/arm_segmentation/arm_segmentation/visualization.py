"""Label images as colours for viewers, reports and the overlay topic."""

import colorsys

import numpy as np


def label_palette(n: int) -> np.ndarray:
    """(n + 1, 3) uint8 colours: black for 0, then well-separated hues (golden-ratio steps)."""
    colours = np.zeros((n + 1, 3), dtype=np.uint8)
    for k in range(1, n + 1):
        hue = (k * 0.618033988749895) % 1.0
        value = 0.95 if k % 2 else 0.75
        colours[k] = np.round(np.array(colorsys.hsv_to_rgb(hue, 0.75, value)) * 255)
    return colours


def colourise(labels: np.ndarray) -> np.ndarray:
    """HxW integer labels -> HxWx3 uint8 (0 = black)."""
    labels = np.asarray(labels)
    return label_palette(int(labels.max()) if labels.size else 0)[labels]


def overlay(rgb: np.ndarray, labels: np.ndarray, alpha: float = 0.55) -> np.ndarray:
    """RGB with each instance tinted in its label colour and the background dimmed."""
    colours = colourise(labels).astype(np.float32)
    base = rgb.astype(np.float32)
    objects = (np.asarray(labels) > 0)[..., None]
    out = np.where(objects, (1 - alpha) * base + alpha * colours, 0.6 * base)
    return np.clip(out, 0, 255).astype(np.uint8)
