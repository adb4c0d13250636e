import numpy as np

from arm_segmentation.clustering import flood


def _one_colour(shape):
    return np.full((*shape, 3), 1.0 / 3.0, dtype=np.float32)


def test_flood_fills_same_colour_pixels_from_the_seed():
    labels = np.zeros((5, 9), dtype=np.int64)
    labels[2, 0] = 1
    out = flood(labels, np.ones((5, 9), dtype=bool), _one_colour((5, 9)), iterations=20, max_chroma=0.1)
    assert np.all(out == 1)


def test_flood_stops_at_other_colours_and_outside_the_mask():
    shape = (3, 8)
    labels = np.zeros(shape, dtype=np.int64)
    labels[1, 0] = 1
    chroma = _one_colour(shape)
    chroma[:, 3:5] = (0.8, 0.1, 0.1)
    mask = np.ones(shape, dtype=bool)
    mask[:, 6:] = False
    out = flood(labels, mask, chroma, 20, 0.1)
    assert np.all(out[:, :3] == 1)
    assert np.all(out[:, 3:] == 0)  # a region without a seed of its own is not swallowed


def test_flood_grows_one_ring_per_iteration():
    labels = np.zeros((1, 9), dtype=np.int64)
    labels[0, 0] = 1
    out = flood(labels, np.ones((1, 9), dtype=bool), _one_colour((1, 9)), iterations=3, max_chroma=0.1)
    assert out[0].tolist() == [1, 1, 1, 1, 0, 0, 0, 0, 0]
