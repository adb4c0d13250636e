import numpy as np

from arm_core.boxes import mask_box, resized_intrinsics


def test_box_spans_the_mask_with_the_margin_and_stays_inside_the_image():
    mask = np.zeros((100, 120), dtype=bool)
    mask[40:50, 60:70] = True
    mask[45, 5] = True
    assert mask_box(mask, margin_px=10) == (slice(30, 60), slice(0, 80))
    assert mask_box(mask) == (slice(40, 50), slice(5, 70))
    assert mask_box(np.zeros((4, 4), dtype=bool)) is None


def test_box_of_a_coarse_mask_is_in_the_pixels_of_the_full_image():
    coarse = np.zeros((240, 320), dtype=np.uint8)
    coarse[100:120, 50:90] = 1
    assert mask_box(coarse, margin_px=12, stride=2) == (slice(188, 252), slice(88, 192))
    assert mask_box(coarse, stride=2, shape=(470, 630))[0] == slice(200, 240)
    edge = np.zeros((240, 320), dtype=bool)
    edge[239, 319] = True
    assert mask_box(edge, margin_px=5, stride=2, shape=(479, 639)) == (slice(473, 479), slice(633, 639))


def test_box_of_a_label_image_is_the_grown_bounding_box_of_its_instances_clipped_to_the_image():
    labels = np.zeros((30, 40), np.uint16)
    assert mask_box(labels, 3) is None
    labels[2:5, 30:38] = 1
    labels[10, 12] = 2
    assert mask_box(labels, 3) == (slice(0, 14), slice(9, 40))


def test_resized_intrinsics_keep_each_ray_on_its_pixel():
    K = np.array([[600.0, 0.0, 319.5], [0.0, 610.0, 239.5], [0.0, 0.0, 1.0]])
    half = resized_intrinsics(K, (480, 640), (240, 320))
    assert np.allclose(half, [[300.0, 0.0, 159.5], [0.0, 305.0, 119.5], [0.0, 0.0, 1.0]])
    assert np.allclose(resized_intrinsics(half, (240, 320), (480, 640)), K)
