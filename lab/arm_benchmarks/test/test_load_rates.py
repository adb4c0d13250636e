"""Delivered rates per minute of the load run, and the first minute against the later ones."""

import numpy as np

from arm_benchmarks.robustness.load import medians_by_window, rate_against_first_window, rates_by_window


def _samples(rate_hz_at, duration_s: float = 180.0, period_s: float = 1.0):
    """Running message totals sampled every period_s of a stream whose rate is rate_hz_at(t)."""
    t = np.arange(0.0, duration_s + 1e-9, period_s)
    total = np.concatenate([[0.0], np.cumsum([rate_hz_at(x) * period_s for x in t[:-1]])])
    return [{"t_s": float(a), "count_segmentation": float(c)} for a, c in zip(t, total, strict=True)]


def test_rates_by_window_recovers_a_rate_that_drops_after_the_first_minute():
    samples = _samples(lambda t: 5.0 if t < 60.0 else 3.5)
    assert rates_by_window(samples, "segmentation") == [5.0, 3.5, 3.5]
    summary = rate_against_first_window(rates_by_window(samples, "segmentation"))
    assert summary == {"first_hz": 5.0, "later_median_hz": 3.5, "later_lowest_hz": 3.5, "later_within_tolerance": 0.0}


def test_a_steady_rate_is_within_tolerance_and_short_runs_give_nothing():
    steady = rates_by_window(_samples(lambda t: 4.0), "segmentation")
    assert rate_against_first_window(steady)["later_within_tolerance"] == 1.0
    assert rates_by_window(_samples(lambda t: 4.0, duration_s=30.0), "segmentation") == []
    assert rate_against_first_window([4.0]) is None and rate_against_first_window([0.0, 4.0]) is None


def test_medians_by_window_leave_out_missing_samples():
    value = [200.0 if t < 60 else (float("nan") if t % 2 else 300.0) for t in range(150)]
    samples = [{"t_s": float(t), "frame_ms": v} for t, v in enumerate(value)]
    assert medians_by_window(samples, "frame_ms") == [200.0, 300.0]
