import numpy as np
from seg_fixtures import Box, look_at, render

from arm_core.camera import backproject_image, transform_points
from arm_segmentation.fragments import FragmentParams, contact_counts
from arm_segmentation.overhangs import OverhangParams, join_overhangs, space_below
from arm_segmentation.table_plane import SupportLevel

TABLE = SupportLevel(0.0, 1.0, np.zeros((0, 3)), np.zeros((0, 2)))  # no footprint: holds every point
T_WORLD_CAMERA = look_at((-0.6, 0.1, 0.6), (0.0, 0.0, 0.06))
PARAMS = OverhangParams()


def joined(boxes):
    """(instances before, after join_overhangs) of the ray-cast boxes, each box its own instance."""
    _, depth, labels, K = render(boxes, T_WORLD_CAMERA)
    out = join_overhangs(labels, depth, K, T_WORLD_CAMERA, [TABLE], PARAMS)
    return len(np.unique(labels[labels > 0])), len(np.unique(out[out > 0])), labels, out


def test_a_handle_standing_off_a_body_joins_it():
    """A 3 x 3 cm bar 8 cm long at 10-13 cm, sticking out of a 8 x 8 x 20 cm body's side: the table
    is seen below it."""
    body = Box((0.0, 0.0, 0.10), (0.04, 0.04, 0.10))
    handle = Box((0.0, 0.08, 0.115), (0.015, 0.04, 0.015))
    before, after, labels, out = joined([body, handle])
    assert (before, after) == (2, 1)
    assert np.all(out[labels > 0] == 1)


def test_a_box_on_a_box_stays_apart():
    lower = Box((0.0, 0.0, 0.04), (0.06, 0.06, 0.04))
    upper = Box((0.0, 0.0, 0.11), (0.04, 0.04, 0.03), rgb=(60, 60, 200))
    before, after, labels, out = joined([lower, upper])
    assert (before, after) == (2, 2)
    assert np.array_equal(out, labels)


def test_a_tall_box_seen_above_a_nearer_one_stays_apart():
    """A 20 cm box right behind a 10 cm one: the camera sees only the tall box's upper part, and the
    space below it is hidden behind the nearer box."""
    near = Box((-0.06, 0.0, 0.05), (0.04, 0.06, 0.05))
    far = Box((0.03, 0.0, 0.10), (0.05, 0.05, 0.10), rgb=(60, 160, 60))
    before, after, labels, out = joined([near, far])
    assert (before, after) == (2, 2)
    assert np.array_equal(out, labels)


def test_a_part_that_touches_nothing_stays():
    """A bar in the air touching no instance has nothing to join."""
    bar = Box((0.0, 0.0, 0.15), (0.04, 0.04, 0.015))
    other = Box((0.0, 0.2, 0.05), (0.04, 0.04, 0.05), rgb=(60, 60, 200))
    before, after, labels, out = joined([bar, other])
    assert (before, after) == (2, 2)


def evidence(boxes, part: int, carrier: int):
    """What join_overhangs weighs besides where the contact lies, for instance `part` against
    `carrier`: (low height above the table m, share of the samples below it seen empty, share of its
    outline along the carrier)."""
    _, depth, labels, K = render(boxes, T_WORLD_CAMERA)
    points = transform_points(backproject_image(depth, K, np.float64), T_WORLD_CAMERA)
    mine = points[(labels == part) & (depth > 0)]
    columns = mine[np.linspace(0, len(mine) - 1, PARAMS.columns).astype(np.int64)]
    below = space_below(columns, 0.0, labels, depth, K, T_WORLD_CAMERA, PARAMS)
    touching, outline = contact_counts(labels, depth, FragmentParams())
    low_m = np.percentile(mine[:, 2], PARAMS.low_percentile)
    return low_m, below.empty / below.sampled, touching[part, carrier] / outline[part]


def assert_only_the_contact_keeps_them_apart(boxes, part: int, carrier: int):
    low_m, free_share, contact_share = evidence(boxes, part, carrier)
    assert low_m > PARAMS.min_height_m and free_share >= PARAMS.min_free_share
    assert contact_share >= PARAMS.min_contact_share
    before, after, labels, out = joined(boxes)
    assert (before, after) == (2, 2)
    assert np.array_equal(out, labels)


def test_a_plate_resting_on_a_pillar_stays_apart():
    """A 5 x 14 x 1.5 cm plate on a 5 x 5 x 15 cm pillar, overhanging it to both sides: the table is
    seen below it and it touches the pillar at its depth, but only along its bottom edge (a lamp's
    shade over its stem)."""
    pillar = Box((0.0, 0.0, 0.075), (0.025, 0.025, 0.075))
    plate = Box((0.0, 0.0, 0.1575), (0.025, 0.07, 0.0075), rgb=(60, 60, 200))
    assert_only_the_contact_keeps_them_apart([pillar, plate], part=2, carrier=1)


def test_a_part_under_a_slab_stays_apart():
    """A 5 x 5 x 6 cm block held at 8-14 cm under a 6 x 18 x 2 cm slab (the ray cast has no gravity):
    the table is seen below it, but the slab touches it only along its top edge (an object mostly
    hidden under another that leans on it)."""
    slab = Box((0.0, 0.0, 0.15), (0.03, 0.09, 0.01), rgb=(60, 60, 200))
    block = Box((0.0, 0.0, 0.11), (0.025, 0.025, 0.03))
    assert_only_the_contact_keeps_them_apart([slab, block], part=2, carrier=1)


def test_a_block_on_its_own_pillar_beside_a_box_stays_apart():
    """A 12 x 16 x 6 cm block on a 2.4 cm pillar of its own, flush against a 20 cm box's side: the
    table is seen below most of it and the box touches its side, but the pillar's surface right below
    it is a third instance it can rest on (a lamp's shade over its stem)."""
    box = Box((0.0, 0.11, 0.1), (0.06, 0.06, 0.1), rgb=(60, 160, 60))
    block = Box((0.0, -0.03, 0.18), (0.06, 0.08, 0.03), rgb=(60, 60, 200))
    pillar = Box((-0.045, -0.03, 0.075), (0.012, 0.012, 0.075))
    boxes = [box, block, pillar]
    _, depth, labels, K = render(boxes, T_WORLD_CAMERA)
    without_rest_rule = join_overhangs(labels, depth, K, T_WORLD_CAMERA, [TABLE], OverhangParams(max_rest_share=1.0))
    assert len(np.unique(without_rest_rule[without_rest_rule > 0])) == 2, "the scene tests the rest rule"
    assert np.array_equal(join_overhangs(labels, depth, K, T_WORLD_CAMERA, [TABLE], PARAMS), labels)
