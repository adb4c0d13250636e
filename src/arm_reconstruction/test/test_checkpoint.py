import numpy as np
import pytest
import torch

from arm_reconstruction.checkpoint import (
    CheckpointError,
    default_checkpoint_path,
    load_checkpoint,
    read_checkpoint,
    save_checkpoint,
)
from arm_reconstruction.network import build_model, predict_occupancy


@pytest.fixture
def saved(tmp_path):
    torch.manual_seed(0)
    model = build_model("arm", resolution=16)
    path = tmp_path / "arm.pt"
    save_checkpoint(path, model, {"trained_on": "unit test"}, {"iterations": 0, "loss": np.float32(1.5)})
    return model, path


def test_round_trip_keeps_weights_and_config(saved):
    model, path = saved
    loaded, config = load_checkpoint(path, expected_variant="arm", expected_resolution=16)
    assert config["variant"] == "arm" and config["resolution"] == 16 and config["in_channels"] == 4
    assert config["trained_on"] == "unit test" and config["extra"] == {"iterations": 0, "loss": 1.5}
    grids = (np.random.default_rng(0).random((2, 4, 16, 16, 16)) > 0.5).astype(np.float32)
    np.testing.assert_allclose(predict_occupancy(model, grids), predict_occupancy(loaded, grids), atol=1e-6)
    assert not loaded.training


def test_mismatches_are_refused(saved, tmp_path):
    _, path = saved
    with pytest.raises(CheckpointError, match="variant 'arm', expected 'baseline'"):
        load_checkpoint(path, expected_variant="baseline")
    with pytest.raises(CheckpointError, match="resolution 16, expected 32"):
        load_checkpoint(path, expected_resolution=32)
    with pytest.raises(CheckpointError, match="contradicts"):
        save_checkpoint(tmp_path / "x.pt", build_model("arm", 16), {"variant": "baseline"})


def test_corrupt_truncated_tampered_and_missing_files(saved, tmp_path):
    _, path = saved
    data = path.read_bytes()
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match="corrupt or truncated"):
        load_checkpoint(truncated)
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"not a checkpoint at all")
    with pytest.raises(CheckpointError):
        load_checkpoint(garbage)
    payload = torch.load(path, weights_only=True)
    name = next(iter(payload["state_dict"]))
    payload["state_dict"][name] += 0.01
    tampered = tmp_path / "tampered.pt"
    torch.save(payload, tampered)
    with pytest.raises(CheckpointError, match="checksum"):
        load_checkpoint(tampered)
    payload = torch.load(path, weights_only=True)
    payload["config"]["in_channels"] = 1
    torch.save(payload, tampered)
    with pytest.raises(CheckpointError):
        read_checkpoint(tampered)
    torch.save({"weights": 1}, tampered)
    with pytest.raises(CheckpointError, match="not an ARM reconstruction checkpoint"):
        load_checkpoint(tampered)
    with pytest.raises(CheckpointError, match="not found"):
        load_checkpoint(tmp_path / "missing.pt")


def test_default_paths_are_per_variant():
    assert default_checkpoint_path("arm").name == "arm.pt"
    assert default_checkpoint_path("baseline").parent.name == "checkpoints"
