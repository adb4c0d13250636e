"""A synthetic dataset of boxes in the trainer's shard format: a small, fully known training set for
smoke runs of datagen's readers, the trainer and the benchmarks."""

import numpy as np

from arm_training.reconstruction import datagen
from arm_training.reconstruction.train import TrainConfig


def box_samples(n: int, resolution: int, rng: np.random.Generator) -> dict:
    d = resolution
    columns = {key: [] for key in datagen._SAMPLE_KEYS}
    for index in range(n):
        occupancy = np.zeros((d, d, d), bool)
        lo = rng.integers(d // 4, d // 2, size=2)
        size = rng.integers(2, d // 4, size=3)
        occupancy[lo[0] : lo[0] + size[0], lo[1] : lo[1] + size[1], : size[2]] = True
        others = np.zeros((d, d, d), bool)
        others[:, : d // 8, : d // 4] = True
        visible = occupancy & ~np.roll(occupancy, -1, axis=2)  # the top face
        observed_empty = np.zeros((d, d, d), bool)
        observed_empty[..., size[2] + 1 :] = True
        grid = np.stack([visible, others, observed_empty & ~others, ~(visible | others | observed_empty)])
        columns["grids"].append(grid)
        columns["occupancy"].append(occupancy)
        columns["others"].append(others)
        columns["visible_fraction"].append(float(rng.uniform(0.2, 1.0)))
        columns["visible_pixels"].append(100)
        columns["category"].append("box")
        columns["object_scale"].append(1.0)
        columns["scene_index"].append(0)
        columns["view_index"].append(0)
        columns["object_index"].append(index)
        columns["grid_origin_world"].append(np.zeros(3))
        columns["voxel_size_m"].append(0.01)
        columns["table_height_m"].append(0.0)
        columns["T_world_camera"].append(np.eye(4))
    return columns


def tiny_train_config(data_root, out_path, variant="arm", steps=3, **overrides):
    """A TrainConfig for a few CPU steps of a small network on a box dataset (tests only)."""
    values = dict(
        variant=variant,
        data=str(data_root),
        out=str(out_path),
        steps=steps,
        batch_size=4,
        base_channels=8,
        device="cpu",
        checkpoint_every=1,
        eval_every=2,
        eval_samples=4,
    )
    values.update(overrides)
    return TrainConfig(**values)


def write_box_dataset(
    root,
    split: str,
    shards: int,
    per_shard: int,
    resolution: int = 16,
    seed: int = 0,
    k: float = 4.0,
    first_shard: int = 0,
):
    for shard_seed in range(first_shard, first_shard + shards):
        rng = np.random.default_rng([seed, shard_seed])
        arrays = datagen._to_arrays(box_samples(per_shard, resolution, rng), shard_seed, split, resolution, k, "boxes")
        datagen.write_shard(datagen.shard_path(root, split, shard_seed), arrays)
    return datagen.write_manifest(root, split, {"synthetic": "boxes"})
