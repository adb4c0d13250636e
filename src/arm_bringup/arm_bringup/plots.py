"""The demo's figures: camera + segmentation, reconstruction vs ground truth, before/after the task."""

import pathlib

import matplotlib
import numpy as np

from arm_bringup.scenes import render_scene_rgb
from arm_core.boxes import mask_box
from arm_core.camera import look_at
from arm_interfaces.msg import ReconstructedObjectArray
from arm_segmentation.visualization import overlay

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)

SIDE_VIEW = look_at((0.0, -0.9, 0.45), (0.0, 0.0, 0.05))  # T_world_camera of the side view


def _save(fig, axes, path: pathlib.Path, dpi: int) -> None:
    for a in np.ravel(axes):
        a.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)


def plot_camera_segmentation(path, rgb, depth_m, labels, segmented: bool, title: str) -> None:
    """Camera image, depth and the instances (segmentation, or ground truth without it) tinted and
    numbered with their ids, the ids of the meshes on /arm/meshes, cropped to the objects."""
    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    axes[0].imshow(rgb)
    axes[0].set_title(title)
    axes[1].imshow(np.where(depth_m > 0, depth_m, np.nan), cmap="viridis")
    axes[1].set_title("depth (m, noisy)")
    crop = mask_box(labels, margin_px=24) or (slice(None), slice(None))
    axes[2].imshow(overlay(rgb[crop], labels[crop]))
    ids = [int(k) for k in np.unique(labels[crop]) if k > 0]
    for k in ids:
        rows, cols = np.nonzero(labels[crop] == k)
        axes[2].text(cols.mean(), rows.mean(), str(k), color="white", fontsize=8, ha="center", va="center",
                     bbox={"facecolor": "black", "alpha": 0.6, "pad": 1, "linewidth": 0})  # fmt: skip
    name = "segmentation" if segmented else "ground-truth labels (no segmentation)"
    axes[2].set_title(f"{name}: {len(ids)} instances, by id")
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
