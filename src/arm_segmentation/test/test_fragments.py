import numpy as np
from seg_fixtures import intrinsics

from arm_segmentation.fragments import FragmentParams, absorb_fragments, visible_areas_m2

K = intrinsics(640, 480)
PARAMS = FragmentParams()


def scene():
    """A box face at 1 m (instance 1), a 5 x 5 px patch on it at its depth (2), a 60 x 60 px object
    0.2 m behind touching the box's side (3), a lone 3 x 3 px speck at 0.9 m (4) and a lone
    25 x 25 px object at 0.8 m (5)."""
    labels = np.zeros((480, 640), np.uint16)
    depth = np.full((480, 640), 1.5, np.float32)
    labels[100:250, 100:250], depth[100:250, 100:250] = 1, 1.0
    labels[150:155, 150:155] = 2
    labels[120:180, 250:310], depth[120:180, 250:310] = 3, 1.2
    labels[400:403, 400:403], depth[400:403, 400:403] = 4, 0.9
    labels[300:325, 500:525], depth[300:325, 500:525] = 5, 0.8
    return labels, depth


def test_visible_area_of_a_face_on_patch():
    labels, depth = scene()
    areas = visible_areas_m2(labels, depth, K)
    assert np.isclose(areas[1], (150 * 1.0 / K[0, 0]) ** 2 - 25 / K[0, 0] ** 2, rtol=1e-6)


def test_patch_joins_its_object_a_speck_goes_and_objects_stay():
    labels, depth = scene()
    areas = visible_areas_m2(labels, depth, K)
    assert areas[2] < PARAMS.min_speck_area_m2 and areas[4] < PARAMS.min_speck_area_m2
    assert PARAMS.min_speck_area_m2 < areas[5] < PARAMS.min_instance_area_m2
    out = absorb_fragments(labels, depth, K, PARAMS)
    assert np.all(out[150:155, 150:155] == out[100, 100]) and out[100, 100] > 0, "patch absorbed by the box"
    assert np.all(out[400:403, 400:403] == 0), "lone speck dropped"
    assert out[130, 280] not in (0, out[100, 100]), "the object behind the box is not its fragment"
    assert out[310, 510] > 0, "a small object on its own stays"
    assert sorted(np.unique(out[out > 0])) == [1, 2, 3]


def test_no_fragment_leaves_labels_unchanged():
    labels, depth = scene()
    labels[labels == 2] = 1
    labels[labels == 4] = 0
    labels[labels == 5] = 0
    out = absorb_fragments(labels, depth, K, PARAMS)
    assert np.array_equal(out, labels)


def test_a_strip_between_two_objects_joins_the_one_it_touches_most():
    """A 6 x 40 px strip at 1 m between two boxes at its depth, along 40 px of one and 25 px of the
    other: neither alone borders most of its outline, both together do."""
    labels = np.zeros((480, 640), np.uint16)
    depth = np.full((480, 640), 1.5, np.float32)
    labels[100:300, 100:200], depth[100:300, 100:200] = 1, 1.0
    labels[100:140, 200:206], depth[100:140, 200:206] = 2, 1.0
    labels[100:125, 206:300], depth[100:125, 206:300] = 3, 1.0
    out = absorb_fragments(labels, depth, K, PARAMS)
    assert np.all(out[100:140, 200:206] == out[150, 150]) and len(np.unique(out[out > 0])) == 2


def test_a_strip_along_an_edge_joins_its_object_and_a_small_object_beside_a_box_stays():
    """At 1 m: a 5 x 40 px strip bordering a box along 40 px (about 45 % of its outline: one long
    side), the table around the rest, joins the box; a 20 x 20 px object touching the box along one
    side (a quarter of its outline) stays an object."""
    labels = np.zeros((480, 640), np.uint16)
    depth = np.full((480, 640), 1.5, np.float32)
    labels[100:300, 100:200], depth[100:300, 100:200] = 1, 1.0
    labels[150:190, 200:205], depth[150:190, 200:205] = 2, 1.0
    labels[250:270, 200:220], depth[250:270, 200:220] = 3, 1.0
    areas = visible_areas_m2(labels, depth, K)
    assert areas[2] < PARAMS.min_instance_area_m2 and PARAMS.min_speck_area_m2 < areas[3] < PARAMS.min_instance_area_m2
    out = absorb_fragments(labels, depth, K, PARAMS)
    assert np.all(out[150:190, 200:205] == out[100, 100]), "the strip is part of the box"
    assert out[260, 210] not in (0, out[100, 100]), "the small object beside the box stays itself"
