import cv2
import numpy as np
import pytest

from arm_core.camera import intrinsics
from arm_core.distortion import DistortionError, Undistorter, is_distorted

WIDTH, HEIGHT = 640, 480
K = intrinsics(WIDTH, HEIGHT, fovy_deg=60.0)
COEFFICIENTS = {
    "plumb_bob": [-0.28, 0.09, 0.001, -0.0015, -0.012],
    "rational_polynomial": [0.4, -0.05, 0.0008, 0.0005, 0.002, 0.7, 0.02, 0.01],
    "equidistant": [-0.02, 0.01, -0.004, 0.001],
}


def dot_centres():
    u, v = np.meshgrid(np.linspace(60, WIDTH - 60, 7), np.linspace(50, HEIGHT - 50, 5))
    return np.stack([u.ravel(), v.ravel()], 1)


def distort(points_px, model, D):
    """Where ideal pinhole pixels land in the distorted image."""
    normalized = (points_px - K[:2, 2]) / np.diag(K)[:2]
    object_points = np.concatenate([normalized, np.ones((len(normalized), 1))], 1)[:, None, :]
    rvec = tvec = np.zeros(3)
    if model == "equidistant":
        projected, _ = cv2.fisheye.projectPoints(object_points, rvec, tvec, K, np.asarray(D))
    else:
        projected, _ = cv2.projectPoints(object_points, rvec, tvec, K, np.asarray(D))
    return projected.reshape(-1, 2)


def draw_dots(centres_px, radius_px=4.0):
    """Float image of soft discs; with the depth image, one disc per centre at depth 1 m + 0.1 m * index."""
    u, v = np.meshgrid(np.arange(WIDTH) + 0.0, np.arange(HEIGHT) + 0.0)
    image = np.zeros((HEIGHT, WIDTH), np.float32)
    depth = np.zeros((HEIGHT, WIDTH), np.float32)
    for i, (cu, cv) in enumerate(centres_px):
        r = np.hypot(u - cu, v - cv)
        image = np.maximum(image, np.clip(radius_px + 0.5 - r, 0, 1))
        depth[r < radius_px] = 1.0 + 0.1 * i
    return image, depth


def centroids(image, centres_px, window_px=9):
    found = []
    u, v = np.meshgrid(np.arange(WIDTH), np.arange(HEIGHT))
    for cu, cv in centres_px:
        near = (np.abs(u - cu) <= window_px) & (np.abs(v - cv) <= window_px)
        w = image * near
        found.append([(w * u).sum() / w.sum(), (w * v).sum() / w.sum()])
    return np.array(found)


@pytest.mark.parametrize("model", sorted(COEFFICIENTS))
def test_distorted_image_comes_back_within_a_pixel(model):
    D = COEFFICIENTS[model]
    ideal = dot_centres()
    distorted_centres = distort(ideal, model, D)
    assert np.abs(distorted_centres - ideal).max() > 3.0  # the distortion is real
    image, depth = draw_dots(distorted_centres)
    rgb = (np.repeat(image[..., None], 3, axis=2) * 255).astype(np.uint8)
    rgb_out, depth_out = Undistorter().undistort(rgb, depth, model, D, K)
    assert rgb_out.shape == rgb.shape and depth_out.shape == depth.shape
    assert np.abs(centroids(rgb_out[..., 0].astype(float), ideal) - ideal).max() < 1.0
    # depth is resampled by nearest neighbour: only values of the input, each disc at its own depth
    assert set(np.unique(depth_out)) <= set(np.unique(depth))
    for i, (cu, cv) in enumerate(np.round(ideal).astype(int)):
        assert depth_out[cv, cu] == pytest.approx(1.0 + 0.1 * i)


def test_zero_coefficients_are_used_as_is():
    rgb = np.zeros((HEIGHT, WIDTH, 3), np.uint8)
    depth = np.ones((HEIGHT, WIDTH), np.float32)
    out_rgb, out_depth = Undistorter().undistort(rgb, depth, "plumb_bob", [0.0] * 5, K)
    assert out_rgb is rgb and out_depth is depth
    assert not is_distorted("", [])
    assert not is_distorted("some_vendor_model", [0.0, 0.0])


@pytest.mark.parametrize(
    "model, D, reason",
    [
        ("kannala_brandt_x", [0.1, 0.0, 0.0, 0.0], "not supported"),
        ("", [0.1, 0.0, 0.0, 0.0, 0.0], "not supported"),
        ("plumb_bob", [0.1, 0.0, 0.0], "needs 4 or 5 coefficients"),
        ("rational_polynomial", [0.1] * 9, "needs 8 or 12 or 14 coefficients"),
        ("equidistant", [0.1, float("nan"), 0.0, 0.0], "not finite"),
    ],
)
def test_unusable_distortion_is_refused(model, D, reason):
    with pytest.raises(DistortionError, match=reason):
        is_distorted(model, D)


def test_maps_are_cached_per_camera():
    undistorter = Undistorter(max_cached=2)
    first = undistorter.maps("plumb_bob", COEFFICIENTS["plumb_bob"], K, WIDTH, HEIGHT)
    assert undistorter.maps("plumb_bob", COEFFICIENTS["plumb_bob"], K, WIDTH, HEIGHT) is first
    undistorter.maps("plumb_bob", [0.1, 0, 0, 0, 0], K, WIDTH, HEIGHT)
    undistorter.maps("plumb_bob", [0.2, 0, 0, 0, 0], K, WIDTH, HEIGHT)
    assert len(undistorter._maps) == 2
