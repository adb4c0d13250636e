import numpy as np

from arm_benchmarks.grid_floor import parse_grid, reaches_grid_boundary, summarize


def test_grid_text_and_boundary():
    assert parse_grid("2.5:48") == (2.5, 48)
    occupancy = np.zeros((8, 8, 8), bool)
    occupancy[3:5, 3:5, 0:3] = True
    assert not reaches_grid_boundary(occupancy), "resting on the table (bottom layer) is not cut"
    occupancy[3, 3, 7] = True
    assert reaches_grid_boundary(occupancy)


def test_summary_counts_objects_without_occupancy_as_empty():
    rows = [(0.004, 0.007, False, 0.9), (None, 0.007, True, None), (0.002, 0.005, True, 0.8)]
    summary = summarize({"2:32": rows})["2:32"]
    assert summary["objects"] == 3 and summary["empty"] == 1
    assert np.isclose(summary["chamfer_mm_mean"], 3.0) and np.isclose(summary["cut_fraction"], 2 / 3)
    assert np.isclose(summary["normal_consistency"], 0.85)
