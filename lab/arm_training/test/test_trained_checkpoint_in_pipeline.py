"""A checkpoint written by the project's trainer runs in the product's reconstruction pipeline."""

import numpy as np
import pytest

from arm_benchmarks.robustness.frames import render_frames
from arm_reconstruction.checkpoint import load_checkpoint
from arm_reconstruction.pipeline import ReconstructionSettings, Reconstructor
from arm_training.reconstruction.box_dataset import tiny_train_config, write_box_dataset
from arm_training.reconstruction.train import train


@pytest.fixture(scope="module")
def sim():
    return None, render_frames(6, 320, 240, seed=5)[0]


def args(frame):
    return frame.rgb, frame.depth_m, frame.K, frame.T_world_camera, frame.labels


@pytest.mark.slow
def test_checkpoint_from_the_project_trainer_runs_in_the_pipeline(sim, tmp_path):
    write_box_dataset(tmp_path, "train", shards=1, per_shard=8, seed=0, k=3.0)
    write_box_dataset(tmp_path, "test", shards=1, per_shard=4, seed=1, k=3.0)
    train(tiny_train_config(tmp_path, tmp_path / "arm.pt", "arm", steps=2), progress=False)
    _, frame = sim
    reconstructor = Reconstructor(ReconstructionSettings(checkpoint_path=str(tmp_path / "arm.pt")))
    assert reconstructor.resolution == 16 and reconstructor.checkpoint_config["base_channels"] == 8
    assert reconstructor.k == 3.0, "the grid of the checkpoint's training data"
    assert Reconstructor(ReconstructionSettings(checkpoint_path=str(tmp_path / "arm.pt"), k=2.5)).k == 2.5
    model, _ = load_checkpoint(tmp_path / "arm.pt")
    assert Reconstructor(ReconstructionSettings(), model=model).k == 3.0, "a loaded model carries its grid"
    objects = reconstructor(*args(frame))
    assert [o.id for o in objects] == sorted(int(i) for i in np.unique(frame.labels) if i > 0)
    assert all(o.grid.resolution == 16 for o in objects)
    assert all(o.ok or o.error for o in objects)
