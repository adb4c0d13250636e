import numpy as np
import pytest

from arm_segmentation.merge_model import MergeClassifier, MergeParams, shared_classifier
from arm_segmentation.outline_model import OutlineClassifier, OutlineParams, shared_outline_classifier
from arm_segmentation.perceptron import ROWS_PER_PRODUCT, perceptron_probability, stack_perceptrons

CLASSIFIERS = [
    (MergeClassifier, MergeParams, shared_classifier, "merge classifier"),
    (OutlineClassifier, OutlineParams, shared_outline_classifier, "outline classifier"),
]


@pytest.mark.parametrize("classifier, params, shared, what", CLASSIFIERS)
def test_bad_missing_and_disabled_weights(tmp_path, classifier, params, shared, what):
    (tmp_path / "junk.npz").write_bytes(b"not weights")
    with pytest.raises(ValueError, match=f"not {what} weights"):
        classifier(tmp_path / "junk.npz")
    with pytest.raises(FileNotFoundError):
        shared(params(checkpoint=str(tmp_path / "missing.npz")))
    assert shared(params(enabled=False)) is None
    assert shared(params()) is shared(params())  # the shipped weights load once


def test_probability_in_blocks_equals_one_product():
    rng = np.random.default_rng(0)
    layers = [(rng.normal(size=(5, 8)).astype(np.float32), rng.normal(size=8).astype(np.float32)),
              (rng.normal(size=(8, 1)).astype(np.float32), np.zeros(1, np.float32))]  # fmt: skip
    features = rng.normal(size=(3 * ROWS_PER_PRODUCT + 17, 5)).astype(np.float32)
    expected = 1.0 / (1.0 + np.exp(-(np.maximum(features @ layers[0][0] + layers[0][1], 0.0) @ layers[1][0])[:, 0]))
    mean, scale = np.zeros(5, np.float32), np.ones(5, np.float32)
    assert np.allclose(perceptron_probability(features, mean, scale, layers), expected, atol=1e-6)
    assert perceptron_probability(features[:0], mean, scale, layers).shape == (0,)


def test_a_stack_outputs_the_mean_logit_of_its_members():
    rng = np.random.default_rng(1)

    def member(width):
        shapes = [(5, width), (width, width), (width, 1)]
        return [(0.3 * rng.normal(size=s), 0.3 * rng.normal(size=s[1])) for s in shapes]

    members = [member(4), member(4), member(4)]
    features = rng.normal(size=(40, 5)).astype(np.float32)
    mean, scale = np.zeros(5, np.float32), np.ones(5, np.float32)
    logits = [np.log(p / (1 - p)) for p in (perceptron_probability(features, mean, scale, m) for m in members)]
    expected = 1.0 / (1.0 + np.exp(-np.mean(logits, axis=0)))
    stacked = stack_perceptrons(members)
    assert [w.shape for w, _ in stacked] == [(3, 5, 4), (3, 4, 4), (3, 4, 1)]
    assert np.allclose(perceptron_probability(features, mean, scale, stacked), expected, atol=1e-5)
    with pytest.raises(ValueError, match="layer shapes"):
        stack_perceptrons([members[0], member(6)])
