import json

import numpy as np
import pytest
import torch

from arm_training.reconstruction.box_dataset import box_samples, write_box_dataset
from arm_training.reconstruction.datagen import pack_bits
from arm_training.reconstruction.dataset import (
    DatasetError,
    VoxelDataset,
    random_symmetry,
    unpack_bits,
    verify_manifest,
)


def test_pack_and_unpack_round_trip():
    rng = np.random.default_rng(0)
    grids = rng.random((3, 4, 8, 8, 8)) > 0.5
    np.testing.assert_array_equal(unpack_bits(pack_bits(grids), (4, 8, 8, 8)).numpy(), grids)


def test_dataset_batches_match_what_was_written(tmp_path):
    manifest = write_box_dataset(tmp_path, "train", shards=2, per_shard=5)
    assert manifest["n_samples"] == 10 and manifest["n_shards"] == 2
    dataset = VoxelDataset(tmp_path, "train", verify=True)
    assert len(dataset) == 10 and dataset.resolution == 16 and dataset.seeds == [0, 1] and dataset.k == 4.0
    expected = box_samples(5, 16, np.random.default_rng([0, 1]))
    batch = dataset.batch([5, 9])
    assert batch["grids"].shape == (2, 4, 16, 16, 16) and batch["grids"].dtype == torch.float32
    np.testing.assert_array_equal(batch["occupancy"][0].numpy(), expected["occupancy"][0])
    np.testing.assert_array_equal(batch["grids"][1].numpy(), expected["grids"][4])
    np.testing.assert_array_equal(batch["others"][1].numpy(), expected["others"][4])
    assert batch["visible_fraction"][0].item() == pytest.approx(expected["visible_fraction"][0])


def test_manifest_detects_tampered_shards(tmp_path):
    write_box_dataset(tmp_path, "train", shards=1, per_shard=2)
    verify_manifest(tmp_path / "train")
    shard = next((tmp_path / "train").glob("shard_*.npz"))
    shard.write_bytes(shard.read_bytes()[:-10])
    with pytest.raises(DatasetError):
        verify_manifest(tmp_path / "train")
    manifest = json.loads((tmp_path / "train" / "manifest.json").read_text())
    assert manifest["shards"][0]["samples"] == 2


def test_shards_of_different_grids_are_refused(tmp_path):
    write_box_dataset(tmp_path, "train", shards=1, per_shard=2, k=2.0)
    write_box_dataset(tmp_path, "train", shards=1, per_shard=2, k=4.0, first_shard=1)
    with pytest.raises(DatasetError, match="grid k"):
        VoxelDataset(tmp_path, "train")


def test_missing_split_raises(tmp_path):
    with pytest.raises(DatasetError):
        VoxelDataset(tmp_path, "test")


def test_random_symmetry_keeps_gravity_and_voxel_counts():
    write = box_samples(4, 16, np.random.default_rng(3))
    batch = {
        "grids": torch.tensor(np.stack(write["grids"]), dtype=torch.float32),
        "occupancy": torch.tensor(np.stack(write["occupancy"]), dtype=torch.float32),
        "visible_fraction": torch.zeros(4),
    }
    generator = torch.Generator().manual_seed(0)
    seen = set()
    for _ in range(12):
        out = random_symmetry(batch, generator)
        assert torch.equal(out["occupancy"].sum(dim=(1, 2)), batch["occupancy"].sum(dim=(1, 2)))  # per z layer
        assert torch.equal(out["grids"].sum(dim=(2, 3)), batch["grids"].sum(dim=(2, 3)))
        seen.add(out["occupancy"].numpy().tobytes())
    assert len(seen) > 2


def test_tensor_unpacking_matches_numpy():
    rng = np.random.default_rng(1)
    grids = rng.random((3, 4, 8, 8, 6)) > 0.5
    unpacked = unpack_bits(pack_bits(grids), (4, 8, 8, 6), "cpu")
    assert unpacked.dtype == torch.float32
    reference = np.unpackbits(pack_bits(grids), axis=1, count=4 * 8 * 8 * 6).reshape(grids.shape)
    np.testing.assert_array_equal(unpacked.numpy(), reference)
