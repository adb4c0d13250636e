import pytest

from arm_segmentation.synchronizer import ApproximateTimeSynchronizer


def test_matches_one_item_per_input_within_tolerance():
    sync = ApproximateTimeSynchronizer(3, slop_s=0.01)
    assert sync.add(0, 1.000, "a") is None
    assert sync.add(1, 1.004, "b") is None
    stamps, items = sync.add(2, 0.996, "c")
    assert items == ["a", "b", "c"]
    assert stamps == [1.000, 1.004, 0.996]


def test_rejects_sets_wider_than_tolerance():
    sync = ApproximateTimeSynchronizer(2, slop_s=0.01)
    sync.add(0, 1.0, "a")
    assert sync.add(1, 1.05, "b") is None
    stamps, items = sync.add(0, 1.049, "a2")
    assert items == ["a2", "b"]


def test_emits_the_newest_complete_set_and_drops_older_items():
    sync = ApproximateTimeSynchronizer(2, slop_s=0.001, queue_size=5)
    for t in (1.0, 2.0, 3.0):
        sync.add(0, t, f"rgb{t}")
    stamps, items = sync.add(1, 3.0, "depth3")
    assert items == ["rgb3.0", "depth3"]
    # the older rgb frames were discarded with the match: a late depth for t=2 matches nothing
    assert sync.add(1, 2.0, "depth2") is None
    assert sync.stats.dropped_stale == 1
    assert sync.stats.emitted == 1


def test_a_frame_sent_again_with_the_same_stamps_is_emitted_again():
    sync = ApproximateTimeSynchronizer(2, slop_s=0.001)
    sync.add(0, 3.0, "rgb3")
    assert sync.add(1, 3.0, "depth3")[1] == ["rgb3", "depth3"]
    sync.add(0, 3.0, "rgb3 again")
    assert sync.add(1, 3.0, "depth3 again")[1] == ["rgb3 again", "depth3 again"]
    assert sync.stats.emitted == 2 and sync.stats.dropped_stale == 0


def test_out_of_order_arrivals_are_matched():
    sync = ApproximateTimeSynchronizer(2, slop_s=0.001)
    sync.add(0, 2.0, "a2")
    sync.add(0, 1.0, "a1")
    stamps, items = sync.add(1, 1.0, "b1")
    assert items == ["a1", "b1"]
    stamps, items = sync.add(1, 2.0, "b2")
    assert items == ["a2", "b2"]


def test_queues_are_bounded():
    sync = ApproximateTimeSynchronizer(2, slop_s=0.0, queue_size=3)
    for k in range(100):
        sync.add(0, float(k), k)
    assert len(sync._queues[0]) == 3
    assert sync.add(1, 10.0, "old") is None
    assert sync.add(1, 98.0, "new")[1] == [98, "new"]


def test_invalid_construction_and_index():
    with pytest.raises(ValueError):
        ApproximateTimeSynchronizer(0, 0.01)
    with pytest.raises(ValueError):
        ApproximateTimeSynchronizer(2, -1.0)
    sync = ApproximateTimeSynchronizer(2, 0.01)
    with pytest.raises(IndexError):
        sync.add(2, 0.0, "x")
