import numpy as np

from arm_segmentation.table_plane import TableParams, estimate_support_levels


def _flat_table(noisy_normals: bool):
    """A 1.2 x 0.9 m table at z = 0 seen as a 120 x 160 grid of 7.5 mm pixels; with noisy_normals,
    only one 4x4 block in four faces up (the others tilt 20 degrees), as a real sensor's normals on a
    wooden table break up what faces up into specks."""
    ys, xs = np.mgrid[0:120, 0:160]
    points = np.stack([xs * 0.0075, ys * 0.0075, np.zeros(xs.shape)], -1).astype(np.float32)
    normals = np.zeros_like(points)
    normals[..., 2] = 1.0
    if noisy_normals:
        tilted = ((ys // 4) % 2 == 1) | ((xs // 4) % 2 == 1)
        normals[tilted] = (np.sin(np.radians(20)), 0.0, np.cos(np.radians(20)))
    area = np.full(xs.shape, 0.0075**2, np.float32)
    return points, normals, area, np.ones(xs.shape, bool)


def test_a_table_whose_upward_normals_are_specks_is_still_one_support():
    params = TableParams(min_table_area_m2=0.2)
    (clean,) = estimate_support_levels(*_flat_table(False), params)
    (noisy,) = estimate_support_levels(*_flat_table(True), params)
    assert np.allclose(np.ptp(noisy.hull_xy, axis=0), np.ptp(clean.hull_xy, axis=0), atol=0.03)
    assert 0.2 < noisy.area_m2 / clean.area_m2 < 0.3
