"""Training configuration: the variants and their priors, hyper-parameters, and the loss terms of a batch."""

from __future__ import annotations

import dataclasses
import pathlib

import torch

from arm_training.reconstruction.losses import connectivity_loss, reconstruction_loss, stability_loss

PRIORS = {"baseline": (), "arm-c-s": (), "arm-c": ("stability",), "arm": ("stability", "connectivity")}


@dataclasses.dataclass
class TrainConfig:
    variant: str = "arm"
    data: str = "data/arm_dataset"
    train_split: str = "train"
    test_split: str = "test"
    out: str = ""
    work_dir: str = ""
    steps: int = 5000
    batch_size: int = 16
    lr: float = 2e-4
    pos_weight: float = 1.0
    surface_weight: float = 1.0
    stability_weight: float = 1e-5  # per voxel ~32768x this against the mean cross-entropy (model cards)
    connectivity_weight: float = 1e-4  # 1e-2 diverged here: its detour term inflated the shapes
    connectivity_factor: int = 2
    connectivity_endpoints: int = 16
    base_channels: int = 16  # on the shared 2-core CPU 16 trained ~2.3x faster per step than 32
    augment: bool = True
    device: str = "auto"
    threads: int = 2
    seed: int = 0
    checkpoint_every: int = 200
    eval_every: int = 1000
    eval_samples: int = 512
    final_eval_samples: int = 0
    time_limit_min: float = 0.0
    save_float16: bool = True
    init_from: str = ""

    def __post_init__(self):
        if self.variant not in PRIORS:
            raise ValueError(f"unknown variant {self.variant!r}; choose one of {sorted(PRIORS)}")
        self.out = self.out or f"results/train/{self.variant}/{self.variant}.pt"
        self.work_dir = self.work_dir or str(pathlib.Path(self.out).parent)


def losses_for_batch(logits, batch, config: TrainConfig) -> dict[str, torch.Tensor]:
    """The variant's loss terms (unweighted) and their weighted sum under ``total``."""
    terms = {
        "reconstruction": reconstruction_loss(logits, batch["occupancy"], config.pos_weight, config.surface_weight)
    }
    total = terms["reconstruction"]
    unobserved = batch["grids"][:, 3] > 0.5
    if "stability" in PRIORS[config.variant]:
        terms["stability"] = stability_loss(logits, batch["others"], unobserved)
        total = total + config.stability_weight * terms["stability"]
    if "connectivity" in PRIORS[config.variant]:
        terms["connectivity"] = connectivity_loss(
            logits, unobserved, config.connectivity_factor, config.connectivity_endpoints
        )
        total = total + config.connectivity_weight * terms["connectivity"]
    terms["total"] = total
    return terms
