"""Training and data generation throughput for results/perf."""

from __future__ import annotations

import pathlib
import tempfile
import time

import numpy as np
import torch

from arm_reconstruction.network import build_model
from arm_training.reconstruction import datagen
from arm_training.reconstruction.dataset import VoxelDataset
from arm_training.reconstruction.training.config import TrainConfig, losses_for_batch


def measure_training(data_dir: str | None = None, steps: int = 8, seed: int = 0, threads: int = 2) -> dict:
    """Figures for results/perf: ``datagen_samples_per_s`` (one training shard made from scratch,
    one process) and ``train_samples_per_s`` (``arm`` variant with both priors, the default network
    size, batch 16, CPU with ``threads`` threads)."""
    with tempfile.TemporaryDirectory() as scratch:
        root = pathlib.Path(data_dir or scratch)
        start = time.perf_counter()
        arrays = datagen.generate_shard(seed=10_000_000 + seed, split="train")
        datagen_s = time.perf_counter() - start
        samples_made = len(arrays["visible_fraction"])
        datagen.write_shard(datagen.shard_path(root, "train", 0), arrays)
        dataset = VoxelDataset(root, "train")
        torch.set_num_threads(threads)
        config = TrainConfig(variant="arm", data=str(root), device="cpu")
        model = build_model("arm", dataset.resolution, config.base_channels)
        optimizer = torch.optim.Adam(model.parameters(), lr=config.lr)
        rng = np.random.default_rng(seed)

        def one_step():
            batch = dataset.batch(rng.choice(len(dataset), config.batch_size, replace=len(dataset) < 16))
            logits = model(batch["grids"].contiguous(memory_format=torch.channels_last_3d))
            terms = losses_for_batch(logits, batch, config)
            optimizer.zero_grad(set_to_none=True)
            terms["total"].backward()
            optimizer.step()

        one_step()
        start = time.perf_counter()
        for _ in range(steps):
            one_step()
        train_s = time.perf_counter() - start
    return {
        "datagen_samples_per_s": samples_made / datagen_s,
        "train_samples_per_s": steps * config.batch_size / train_s,
        "train_step_s_cpu": train_s / steps,
        "train_base_channels": config.base_channels,
    }
