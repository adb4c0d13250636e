import numpy as np
import pytest

from arm_core.vectors import channel_sum, vector_length


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("shape", [(7, 3), (48, 64, 3)])
def test_the_same_values_as_numpy_to_the_bit(dtype, shape):
    rng = np.random.default_rng(3)
    values = (rng.normal(size=shape) * rng.uniform(0.0, 1e3, size=shape[:-1] + (1,))).astype(dtype)
    assert np.array_equal(channel_sum(values), values.sum(axis=-1))
    assert np.array_equal(vector_length(values), np.linalg.norm(values, axis=-1))
    assert channel_sum(values).dtype == dtype and vector_length(values).dtype == dtype


def test_strided_views_and_zero_vectors():
    image = np.zeros((4, 6, 3), dtype=np.float32)
    image[1, 2] = (3.0, 4.0, 12.0)
    view = image[::2, 1::2]
    assert vector_length(view).shape == (2, 3)
    assert vector_length(image)[1, 2] == 13.0 and vector_length(image)[0, 0] == 0.0
    assert channel_sum(image)[1, 2] == 19.0
