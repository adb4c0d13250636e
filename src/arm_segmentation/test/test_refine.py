import numpy as np

from arm_segmentation.refine import upsample, upsample_linear


def test_upsample_linear_keeps_working_grid_samples_and_interpolates_between_them():
    full = np.add.outer(np.arange(48.0), 2.0 * np.arange(64.0)).astype(np.float32)  # a linear ramp
    working = full[::2, ::2]
    up = upsample_linear(working, 2, full.shape)
    assert up.shape == full.shape and up.dtype == np.float32
    assert np.allclose(up[::2, ::2], working)  # the pixels the working grid sampled
    assert np.allclose(up[:-1, :-1], full[:-1, :-1], atol=1e-4)  # a ramp is interpolated exactly
    assert np.array_equal(upsample(working, 2, full.shape)[::2, ::2], working)
