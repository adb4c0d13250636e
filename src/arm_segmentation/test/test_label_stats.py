import numpy as np
import pytest
from scipy import ndimage

from arm_segmentation.label_stats import label_maximum, label_minimum


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_label_extremes_match_scipy_including_empty_labels_and_nan(seed):
    rng = np.random.default_rng(seed)
    labels = rng.integers(0, 6, (40, 50))
    labels[labels == 4] = 2  # label 4 has no pixels
    values = rng.normal(size=(40, 50))
    values[rng.random((40, 50)) < 0.05] = np.nan
    values[labels == 5] = np.nan  # every value of label 5 is NaN
    values[labels == 3] = np.where(rng.random((labels == 3).sum()) < 0.5, np.inf, -np.inf)
    ids = np.arange(7)
    np.testing.assert_array_equal(label_maximum(values, labels, 6), ndimage.maximum(values, labels, ids))
    np.testing.assert_array_equal(label_minimum(values, labels, 6), ndimage.minimum(values, labels, ids))
    np.testing.assert_array_equal(label_maximum(values, labels, 3), ndimage.maximum(values, labels, ids[:4]))
