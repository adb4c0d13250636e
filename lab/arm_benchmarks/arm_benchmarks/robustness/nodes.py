"""The nodes of the robustness runs: their ROS names and the reconstruction node's checkpoint."""

from __future__ import annotations

import os
import pathlib

from arm_reconstruction.checkpoint import default_checkpoint_path

ROOT = pathlib.Path(os.environ.get("ARM_ROOT") or pathlib.Path.cwd())
NODE_NAMES = {
    "sim": "sim_node",
    "segmentation": "segmentation_node",
    "reconstruction": "reconstruction_node",
    "planner": "plan_node",
    "record": "bag_recorder",
    "replay": "bag_replayer",
}
SHIPPED_CHECKPOINT = default_checkpoint_path("arm")


def reconstruction_checkpoint() -> pathlib.Path | None:
    """The checkpoint the reconstruction node runs with in robustness runs: ARM_ROBUSTNESS_CHECKPOINT
    if set, else the shipped one; None when neither exists."""
    override = os.environ.get("ARM_ROBUSTNESS_CHECKPOINT")
    path = pathlib.Path(override) if override else SHIPPED_CHECKPOINT
    return path if path.exists() else None


def reconstruction_params() -> dict | None:
    """Parameters of the reconstruction node in robustness runs: its checkpoint (see
    reconstruction_checkpoint) plus ARM_ROBUSTNESS_RECON_PARAMS="name:=value ..."; None without a
    checkpoint."""
    checkpoint = reconstruction_checkpoint()
    if checkpoint is None:
        return None
    params = {"checkpoint_path": str(checkpoint)}
    for item in os.environ.get("ARM_ROBUSTNESS_RECON_PARAMS", "").split():
        name, value = item.split(":=", 1)
        try:
            params[name] = int(value) if value.lstrip("-").isdigit() else float(value)
        except ValueError:
            params[name] = value
    return params
