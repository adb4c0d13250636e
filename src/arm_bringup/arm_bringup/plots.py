"""The demo's figures: camera + segmentation, reconstruction vs ground truth, before/after the task."""

import pathlib

import matplotlib
import numpy as np

from arm_bringup.scenes import render_scene_rgb
from arm_core.camera import look_at
from arm_interfaces.msg import ReconstructedObjectArray

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)

SIDE_VIEW = look_at((0.0, -0.9, 0.45), (0.0, 0.0, 0.05))  # T_world_camera of the side view


def colourise(labels: np.ndarray) -> np.ndarray:
    palette = np.random.default_rng(3).uniform(0.2, 1.0, (int(labels.max()) + 1, 3))
    palette[0] = 0
    return palette[labels]


def _save(fig, axes, path: pathlib.Path, dpi: int) -> None:
    for a in np.ravel(axes):
        a.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)


def plot_camera_segmentation(path, rgb, depth_m, labels, segmented: bool, title: str) -> None:
    """Camera image, depth and a label overlay (segmentation, or ground truth without it)."""
    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    axes[0].imshow(rgb)
    axes[0].set_title(title)
    axes[1].imshow(np.where(depth_m > 0, depth_m, np.nan), cmap="viridis")
    axes[1].set_title("depth (m, noisy)")
    overlay = 0.5 * rgb / 255.0 + 0.5 * colourise(labels)
    axes[2].imshow(np.clip(overlay, 0, 1))
    axes[2].set_title("segmentation overlay" if segmented else "ground-truth labels (no segmentation)")
    _save(fig, axes, path, 90)


def plot_reconstruction_vs_truth(
    path, meshes: ReconstructedObjectArray, truth: ReconstructedObjectArray, T_world_camera
) -> None:
    """Reconstruction and ground truth rendered from the camera and from the side."""
    fig, axes = plt.subplots(2, 2, figsize=(12, 9))
    for row, (name, camera) in enumerate([("camera view", T_world_camera), ("side view", SIDE_VIEW)]):
        axes[row, 0].imshow(render_scene_rgb(meshes, camera))
        axes[row, 0].set_title(f"reconstruction ({meshes.objects[0].method if meshes.objects else ''}), {name}")
        axes[row, 1].imshow(render_scene_rgb(truth, camera))
        axes[row, 1].set_title(f"ground truth, {name}")
    _save(fig, axes, path, 80)


def plot_before_after(path, rgb_before, rgb_after, title_after: str) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    axes[0].imshow(rgb_before)
    axes[0].set_title("before")
    axes[1].imshow(rgb_after)
    axes[1].set_title(title_after)
    _save(fig, axes, path, 90)
