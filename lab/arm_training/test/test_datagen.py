import numpy as np
import pytest
from scipy import ndimage

from arm_sim.objects import HELDOUT_CATEGORIES
from arm_training.reconstruction import datagen
from arm_training.reconstruction.dataset import VoxelDataset, unpack_bits, verify_manifest

SETTINGS = dict(resolution=16, views_per_scene=2, objects_per_scene=(3, 4))


@pytest.fixture(scope="module")
def shard():
    return datagen.generate_shard(seed=3, split="train", **SETTINGS)


def test_shard_holds_consistent_samples(shard):
    n = len(shard["visible_fraction"])
    assert n >= 1 and str(shard["format"]) == datagen.FORMAT and int(shard["resolution"]) == 16
    grids = unpack_bits(shard["grids_bits"], (4, 16, 16, 16)).numpy() > 0.5
    occupancy = unpack_bits(shard["occupancy_bits"], (16, 16, 16)).numpy() > 0.5
    others = unpack_bits(shard["others_bits"], (16, 16, 16)).numpy() > 0.5
    assert grids.shape == (n, 4, 16, 16, 16)
    assert (grids.sum(axis=1) >= 1).all(), "every voxel is occupied, observed empty or unobserved"
    assert not (grids[:, 2] & grids[:, 3]).any()
    assert grids[:, 0].reshape(n, -1).any(axis=1).all(), "every sample shows some of its object"
    assert occupancy.reshape(n, -1).any(axis=1).all(), "ground truth inside the grid"
    overlap = (occupancy & others).sum() / occupancy.sum()
    assert overlap < 0.05, "objects do not interpenetrate"
    own_points_inside = (grids[:, 0] & _dilate(occupancy)).sum() / grids[:, 0].sum()
    assert own_points_inside > 0.8, "observed points lie on the ground-truth object"
    assert ((shard["visible_fraction"] > 0) & (shard["visible_fraction"] <= 1)).all()
    assert (shard["visible_pixels"] >= datagen.MIN_VISIBLE_PIXELS).all()
    assert set(shard["category"]) <= set(__import__("arm_sim.objects").objects.TRAIN_CATEGORIES)


def _dilate(occupancy):
    return np.stack([ndimage.binary_dilation(o, np.ones((3, 3, 3), bool)) for o in occupancy])


def test_generate_writes_manifest_and_resumes(tmp_path, shard):
    datagen.write_shard(datagen.shard_path(tmp_path, "train", 3), shard)  # as a previous run left it
    summary = datagen.generate(tmp_path, "train", n_shards=1, first_seed=3, progress=False, **SETTINGS)
    assert summary["shards_made"] == 0 and summary["n_samples"] == len(shard["visible_fraction"])
    manifest = verify_manifest(tmp_path / "train")
    assert manifest["shards"][0]["file"] == "shard_0000003.npz"
    assert len(VoxelDataset(tmp_path, "train")) == manifest["n_samples"]
    broken = datagen.shard_path(tmp_path, "train", 4)
    broken.write_bytes(b"not a shard")
    assert datagen.shard_sample_count(broken) is None


def test_test_split_uses_heldout_categories():
    shard = datagen.generate_shard(seed=0, split="test", resolution=16, views_per_scene=1, objects_per_scene=(3, 3))

    assert set(shard["category"]) <= set(HELDOUT_CATEGORIES)
    with pytest.raises(ValueError):
        datagen.generate("unused", "validation", n_shards=0)
