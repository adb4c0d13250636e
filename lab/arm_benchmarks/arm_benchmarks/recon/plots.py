"""bench_recon's figures: Chamfer and IoU by visible fraction, stability, qualitative hard cases."""

from __future__ import annotations

import pathlib

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from arm_benchmarks.methods import GROUND_TRUTH
from arm_benchmarks.recon.config import VISIBILITY_BINS
from arm_benchmarks.recon.summary import bin_label

matplotlib.use("Agg")


def plot_by_visibility(summary: dict, path: pathlib.Path) -> None:
    labels = [bin_label(b) for b in VISIBILITY_BINS]
    x = np.arange(len(labels))
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.5))
    geometric = [n for n, m in summary["methods"].items() if m["status"] == "ok" and n != GROUND_TRUTH]
    for k, name in enumerate(geometric):
        bins = summary["methods"][name]["by_visibility"]
        offset = (k - (len(geometric) - 1) / 2) * 0.05
        for ax, key, scale in ((axes[0], "chamfer_m", 1000.0), (axes[1], "iou", 1.0)):
            ci = [bins[b][f"{key}_ci90"] for b in labels]
            mean = np.array([bins[b][key] if bins[b][key] is not None else np.nan for b in labels]) * scale
            low = np.array([c[0] for c in ci], dtype=np.float64) * scale
            high = np.array([c[1] for c in ci], dtype=np.float64) * scale
            yerr = np.stack([np.nan_to_num(mean - low), np.nan_to_num(high - mean)])
            ax.errorbar(
                x + offset, mean, yerr=yerr, marker="o", capsize=3, label=name, linewidth=2.5 if name == "arm" else 1.2
            )
    axes[0].set_ylabel("Chamfer distance (mm, lower is better)")
    axes[1].set_ylabel("volumetric IoU (higher is better)")
    for ax in axes:
        ax.set_xticks(x, labels)
        ax.set_xlabel("visible fraction of the object")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{summary['objects']} objects, {summary['scenes']} scenes; error bars: 90% bootstrap CI")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_stability(summary: dict, path: pathlib.Path) -> None:
    names = [n for n, m in summary["methods"].items() if m["status"] == "ok"]
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.5))
    rates = np.array([summary["methods"][n]["stable_fraction"] or 0.0 for n in names])
    ci = np.array([summary["methods"][n]["stable_ci90"] for n in names], dtype=np.float64).reshape(-1, 2)
    colours = ["tab:green" if n == GROUND_TRUTH else "tab:red" if n == "arm" else "tab:blue" for n in names]
    axes[0].bar(
        names, rates, yerr=np.nan_to_num(np.stack([rates - ci[:, 0], ci[:, 1] - rates])), capsize=4, color=colours
    )
    axes[0].set_ylabel(
        f"fraction moved < {summary['config']['stable_threshold_m'] * 100:.0f} cm "
        f"in {summary['config']['settle_s']:.0f} s"
    )
    axes[0].set_ylim(0, 1.05)
    median = np.array([summary["methods"][n]["displacement_m_median"] or 0.0 for n in names]) * 100
    mean = np.array([summary["methods"][n]["displacement_m_mean"] or 0.0 for n in names]) * 100
    axes[1].bar(names, np.maximum(median, 1e-3), color=colours, label="median")
    axes[1].scatter(names, np.maximum(mean, 1e-3), color="black", marker="_", s=400, label="mean", zorder=3)
    axes[1].axhline(summary["config"]["stable_threshold_m"] * 100, color="grey", linestyle="--", linewidth=1)
    axes[1].set_yscale("log")
    axes[1].set_ylabel("displacement of the object's centre of mass (cm)")
    axes[1].legend()
    for ax in axes:
        ax.tick_params(axis="x", rotation=35)
        ax.grid(alpha=0.3, axis="y")
    axes[0].set_title("physical stability (90% Wilson CI)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _draw_mesh(ax, vertices, faces, centre, half: float, elevation: float, azimuth: float) -> None:
    triangles = np.asarray(vertices, np.float64)[np.asarray(faces, np.int64)]
    if len(triangles):
        normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
        el, az = np.radians(elevation), np.radians(azimuth)
        light = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        shade = 0.3 + 0.7 * np.clip(normals @ light, 0.0, 1.0)
        colours = np.column_stack([shade * 0.55, shade * 0.65, shade * 0.9, np.ones_like(shade)])
        ax.add_collection3d(Poly3DCollection(triangles, facecolors=colours, edgecolors="none"))
    for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre, strict=True):
        setter(c - half, c + half)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elevation, azimuth)
    ax.set_axis_off()


def plot_qualitative(cases: list[dict], path: pathlib.Path) -> None:
    """Rows: hard cases; columns: input view (object tinted, true silhouette outlined) | baseline |
    arm | ground truth, each mesh seen from 90 degrees to the side of the camera."""
    columns = ("input view", "baseline", "arm", GROUND_TRUTH)
    fig = plt.figure(figsize=(12, 3 * len(cases)))
    for row, case in enumerate(cases):
        ax = fig.add_subplot(len(cases), 4, 4 * row + 1)
        image = case["rgb"].astype(np.float64) / 255.0
        image[case["visible"]] = 0.5 * image[case["visible"]] + 0.5 * np.array([1.0, 0.2, 0.2])
        ax.imshow(image)
        ax.contour(case["silhouette"], levels=[0.5], colors="yellow", linewidths=1)
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f"{case['category']}, visible {case['visible_fraction']:.2f}", fontsize=9)
        vertices = np.concatenate([case[name][0] for name in columns[1:]])
        centre = 0.5 * (vertices.min(0) + vertices.max(0))
        half = 0.55 * max(float(np.ptp(vertices, axis=0).max()), 1e-3)
        eye = case["camera_eye"] - centre
        azimuth = float(np.degrees(np.arctan2(eye[1], eye[0]))) + 90.0
        for col, name in enumerate(columns[1:], start=2):
            ax = fig.add_subplot(len(cases), 4, 4 * row + col, projection="3d")
            _draw_mesh(ax, *case[name], centre, half, 25.0, azimuth)
            chamfer = case.get(f"{name}_chamfer_m")
            title = name if chamfer is None else f"{name}: Chamfer {chamfer * 1000:.1f} mm"
            ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
