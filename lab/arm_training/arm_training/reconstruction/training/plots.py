"""Training curves: smoothed loss terms and held-out metrics over the steps."""

from __future__ import annotations

import pathlib

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)


def plot_curves(history: list[dict], evaluations: list[dict], path) -> None:
    figure, axes = plt.subplots(1, 2, figsize=(11, 4))
    steps = np.array([h["step"] for h in history])
    for key in ("total", "reconstruction", "stability", "connectivity"):
        values = np.array([h.get(key, np.nan) for h in history], dtype=float)
        if len(values) and np.isfinite(values).any():
            window = max(1, len(values) // 50)
            smooth = np.convolve(values, np.ones(window) / window, mode="valid")
            axes[0].plot(steps[window - 1 :], smooth, label=key)
    axes[0].set_yscale("symlog", linthresh=1e-3)
    axes[0].set_xlabel("step")
    axes[0].set_title("training losses (unweighted terms, moving average)")
    axes[0].legend()
    if evaluations:
        eval_steps = [e["step"] for e in evaluations]
        for key in ("iou", "iou_occluded", "stable", "single_component"):
            if key in evaluations[0]:
                axes[1].plot(eval_steps, [e[key] for e in evaluations], marker="o", label=key)
        axes[1].set_xlabel("step")
        axes[1].set_title("held-out metrics")
        axes[1].legend()
    figure.tight_layout()
    pathlib.Path(path).parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=100)
    plt.close(figure)
