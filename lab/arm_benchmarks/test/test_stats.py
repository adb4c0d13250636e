import json
import math

import numpy as np
import pytest

from arm_benchmarks.stats import (
    bootstrap_interval,
    json_safe,
    mean,
    median,
    none_if_nan,
    percentile,
    rate,
    wilson_interval,
)


def test_wilson_interval_known_value_and_empty():
    low, high = wilson_interval(8, 10)
    assert low == pytest.approx(0.5408, abs=1e-3) and high == pytest.approx(0.9314, abs=1e-3)
    assert all(math.isnan(v) for v in wilson_interval(0, 0)) and math.isnan(rate(0, 0))


@pytest.mark.parametrize(("k", "n"), [(0, 1), (0, 7), (3, 3), (11, 11), (1, 2), (9, 10)])
def test_wilson_interval_contains_the_rate_within_zero_one(k, n):
    low, high = wilson_interval(k, n)
    assert 0.0 <= low <= rate(k, n) <= high <= 1.0
    if k == 0:
        assert low == 0.0
    if k == n:
        assert high == 1.0


def test_bootstrap_interval_of_the_mean():
    low, high = bootstrap_interval(np.arange(100.0))
    assert low < 49.5 < high and high - low < 20
    assert bootstrap_interval(np.arange(100.0)) == (low, high), "seeded: reproducible"
    assert all(math.isnan(v) for v in bootstrap_interval([]))


def test_empty_samples_are_nan_and_json_null():
    assert mean([1.0, 2.0]) == 1.5 and median([3.0, 1.0, 2.0]) == 2.0 and percentile([0.0, 10.0], 90) == 9.0
    assert all(math.isnan(f([])) for f in (mean, median)) and math.isnan(percentile([], 50))
    assert none_if_nan(float("nan")) is None and none_if_nan((1.0, float("nan"))) == [1.0, None]
    safe = json_safe({"a": (float("inf"), 2.0), "b": [{"c": float("nan")}], "d": "x"})
    assert json.loads(json.dumps(safe, allow_nan=False)) == {"a": [None, 2.0], "b": [{"c": None}], "d": "x"}
