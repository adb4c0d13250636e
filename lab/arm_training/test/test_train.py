import numpy as np
import pytest
import torch

from arm_reconstruction.checkpoint import load_checkpoint, read_checkpoint
from arm_reconstruction.model_cards import write_model_card
from arm_training.reconstruction.box_dataset import tiny_train_config, write_box_dataset
from arm_training.reconstruction.dataset import VoxelDataset
from arm_training.reconstruction.train import main
from arm_training.reconstruction.training.config import PRIORS, TrainConfig, losses_for_batch
from arm_training.reconstruction.training.evaluation import voxel_metrics
from arm_training.reconstruction.training.loop import train


@pytest.fixture(scope="module")
def box_data(tmp_path_factory):
    root = tmp_path_factory.mktemp("boxes")
    write_box_dataset(root, "train", shards=2, per_shard=12, seed=0)
    write_box_dataset(root, "test", shards=1, per_shard=6, seed=1)
    return root


def _config(root, tmp_path, variant="arm", steps=3, **overrides):
    return tiny_train_config(root, tmp_path / f"{variant}.pt", variant, steps, **overrides)


def test_variants_use_their_priors(box_data):
    batch = VoxelDataset(box_data, "train").batch(np.arange(4))
    logits = torch.randn(4, 16, 16, 16, requires_grad=True)
    for variant, priors in PRIORS.items():
        terms = losses_for_batch(logits, batch, TrainConfig(variant=variant))
        assert set(terms) == {"reconstruction", "total", *priors}
        assert torch.isfinite(terms["total"])


def test_train_writes_a_loadable_checkpoint_card_and_curves(box_data, tmp_path):
    result = train(_config(box_data, tmp_path), command="train --test", progress=False)
    assert result["steps"] == 3 and result["test_samples"] == 6
    assert set(result["heldout_metrics"]) >= {"iou", "chamfer_m", "stable", "single_component"}
    model, config = load_checkpoint(tmp_path / "arm.pt", expected_variant="arm", expected_resolution=16)
    assert config["training"]["stability_weight"] == TrainConfig().stability_weight
    assert config["extra"]["command"] == "train --test" and config["extra"]["weights_dtype"] == "float16"
    assert next(model.parameters()).dtype == torch.float32
    assert torch.isfinite(model(torch.zeros(1, 4, 16, 16, 16))).all()
    assert (tmp_path / "curves.png").stat().st_size > 1000
    card = write_model_card(tmp_path / "arm.pt").read_text()
    assert "train --test" in card and "voxel IoU" in card


def test_training_resumes_from_its_state(box_data, tmp_path):
    train(_config(box_data, tmp_path, variant="arm-c", steps=2), progress=False)
    first = read_checkpoint(tmp_path / "arm-c.pt")
    result = train(_config(box_data, tmp_path, variant="arm-c", steps=4), progress=False)
    assert result["steps"] == 4
    history = read_checkpoint(tmp_path / "arm-c.pt")["extra"]["loss_history"]
    assert [h["step"] for h in history] == [1, 2, 3, 4]
    assert first["extra"]["loss_history"] == history[:2]
    with pytest.raises(SystemExit):
        train(_config(box_data, tmp_path, variant="arm", steps=5, out=str(tmp_path / "arm-c.pt")), progress=False)


def test_training_reduces_the_loss_on_boxes(box_data, tmp_path):
    result = train(_config(box_data, tmp_path, variant="arm-c-s", steps=20, lr=3e-3, eval_every=0), progress=False)
    history = read_checkpoint(tmp_path / "arm-c-s.pt")["extra"]["loss_history"]
    assert np.mean([h["total"] for h in history[-4:]]) < 0.5 * np.mean([h["total"] for h in history[:4]])
    assert 0.0 <= result["heldout_metrics"]["iou"] <= 1.0


def test_command_line_rejects_bad_numbers(box_data):
    with pytest.raises(SystemExit):
        main(["--data", str(box_data), "--steps", "0"])
    with pytest.raises(SystemExit):
        main(["--data", str(box_data), "--stability-weight", "-1"])


def test_voxel_metrics_on_constructed_grids():
    d = 12
    truth = np.zeros((3, d, d, d), bool)
    truth[:, 4:8, 4:8, 0:4] = True
    predicted = truth.copy().astype(np.float32)
    predicted[1] = 0
    predicted[1][4:8, 4:8, 6:10] = 1  # floating copy, 6 voxels above
    predicted[2][4:8, 4:8, 6:8] = 1  # a second, disconnected piece
    metrics = voxel_metrics(predicted, truth.astype(np.float32), np.full(3, 0.01), np.zeros((3, d, d, d), np.float32))
    assert metrics["iou"][0] == 1.0 and metrics["chamfer_m"][0] == 0.0
    assert metrics["iou"][1] == 0.0 and metrics["chamfer_m"][1] > 0.06
    assert metrics["stable"].tolist() == [True, False, True]
    assert metrics["single_component"].tolist() == [True, True, False]


def test_ablation_can_start_from_a_shared_trunk(box_data, tmp_path):
    train(_config(box_data, tmp_path / "trunk", variant="arm-c-s", steps=2), progress=False)
    trunk = tmp_path / "trunk" / "state.pt"
    config = _config(box_data, tmp_path / "arm", variant="arm", steps=3, init_from=str(trunk))
    result = train(config, progress=False)
    history = read_checkpoint(tmp_path / "arm" / "arm.pt")["extra"]["loss_history"]
    assert result["steps"] == 3 and "connectivity" in history[-1] and "connectivity" not in history[0]
    with pytest.raises(SystemExit):
        train(_config(box_data, tmp_path / "base", variant="baseline", steps=3, init_from=str(trunk)), progress=False)


def test_fine_tuning_starts_from_a_saved_checkpoint(box_data, tmp_path):
    train(_config(box_data, tmp_path / "first", variant="arm", steps=2), progress=False)
    shipped = tmp_path / "first" / "arm.pt"
    weights = read_checkpoint(shipped)["state_dict"]
    config = _config(box_data, tmp_path / "tuned", variant="arm", steps=4, init_from=str(shipped))
    result = train(config, progress=False)
    assert result["steps"] == 4
    history = read_checkpoint(tmp_path / "tuned" / "arm.pt")["extra"]["loss_history"]
    assert [h["step"] for h in history] == [1, 2, 3, 4]
    model = load_checkpoint(tmp_path / "tuned" / "arm.pt")[0]
    moved = [not torch.equal(weights[name].float(), value.half().float()) for name, value in model.state_dict().items()]
    assert any(moved)
    with pytest.raises(SystemExit):
        train(_config(box_data, tmp_path / "base", variant="baseline", steps=3, init_from=str(shipped)), progress=False)
