import copy

import numpy as np
import pytest
import torch

from arm_reconstruction.network import (
    METHODS,
    VARIANTS,
    build_model,
    canonical_method,
    model_config,
    predict_occupancy,
    prepare_for_inference,
)

torch.set_num_threads(2)


@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_every_variant_maps_grids_to_logits(variant):
    model = build_model(variant, resolution=8, base_channels=32)
    grids = torch.rand(2, VARIANTS[variant], 8, 8, 8)
    logits = model(grids)
    assert logits.shape == (2, 8, 8, 8)
    assert model_config(model) == {
        "architecture": "unet3d-v2",
        "variant": variant,
        "in_channels": VARIANTS[variant],
        "resolution": 8,
        "base_channels": 32,
    }
    logits.sum().backward()
    assert all(p.grad is not None for p in model.parameters())


def test_predict_occupancy_gives_probabilities_and_reads_the_right_channels():
    torch.manual_seed(0)
    grids = (np.random.default_rng(0).random((3, 4, 16, 16, 16)) > 0.7).astype(np.float32)
    baseline = build_model("baseline", 16)
    probabilities = predict_occupancy(baseline, grids, "cpu", batch_size=2)
    assert probabilities.shape == (3, 16, 16, 16) and probabilities.dtype == np.float32
    assert np.all((probabilities >= 0) & (probabilities <= 1))
    only_f1 = predict_occupancy(baseline, grids[:, :1], "cpu")
    np.testing.assert_allclose(probabilities, only_f1, atol=1e-5)
    arm = build_model("arm", 16)
    changed = grids.copy()
    changed[:, 3] = 1 - changed[:, 3]
    assert not np.allclose(predict_occupancy(arm, grids), predict_occupancy(arm, changed))
    assert predict_occupancy(arm, np.zeros((0, 4, 16, 16, 16), np.float32)).shape == (0, 16, 16, 16)
    with pytest.raises(ValueError, match="input channels"):
        predict_occupancy(arm, grids[:, :2])


def test_batched_prediction_equals_one_by_one():
    model = build_model("arm", 16)
    grids = (np.random.default_rng(1).random((4, 4, 16, 16, 16)) > 0.5).astype(np.float32)
    together = predict_occupancy(model, grids, batch_size=4)
    alone = np.concatenate([predict_occupancy(model, grids[i : i + 1]) for i in range(4)])
    np.testing.assert_allclose(together, alone, atol=1e-5)


def test_names_and_bad_settings():
    assert canonical_method("ARM") == "arm"
    assert canonical_method("baseline+ray carving") == "baseline+ray-carving"
    assert canonical_method("baseline+e") == "baseline+E"
    assert set(METHODS) == {"arm", "arm-c", "arm-c-s", "baseline", "baseline+ray-carving", "baseline+E"}
    with pytest.raises(ValueError, match="unknown reconstruction method"):
        canonical_method("genre")
    with pytest.raises(ValueError, match="unknown network variant"):
        build_model("arm-x")
    with pytest.raises(ValueError, match="multiple of 8"):
        build_model("arm", 20)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_cuda_matches_cpu():
    model = build_model("arm", 16)
    grids = (np.random.default_rng(2).random((2, 4, 16, 16, 16)) > 0.5).astype(np.float32)
    on_cpu = predict_occupancy(model, grids, "cpu")
    np.testing.assert_allclose(on_cpu, predict_occupancy(model, grids, "cuda"), atol=1e-3)


def test_inference_preparation_keeps_the_outputs():
    model = build_model("arm", 16)
    grids = (np.random.default_rng(3).random((3, 4, 16, 16, 16)) > 0.5).astype(np.float32)
    before = predict_occupancy(model, grids)
    prepared = prepare_for_inference(copy.deepcopy(model), "cpu")
    np.testing.assert_allclose(predict_occupancy(prepared, grids), before, atol=1e-5)
