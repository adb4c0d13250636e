"""Summary statistics of the benchmarks: one convention for every interval and every empty sample.

Intervals are (low, high) tuples of floats; a statistic of no data is nan (JSON writers turn it into
null with json_safe). All intervals are 90% by default, as the benchmark reports state.
"""

from __future__ import annotations

import math

import numpy as np

Z_90 = 1.6448536269514722  # standard normal quantile of 0.95: two-sided 90%
NAN_INTERVAL = (float("nan"), float("nan"))


def wilson_interval(successes: int, n: int, z: float = Z_90) -> tuple[float, float]:
    """Wilson score interval of a success rate successes / n; (nan, nan) for n = 0. The interval
    always contains the rate (at 0 or 1 rounding could otherwise put an end a hair past it)."""
    if n == 0:
        return NAN_INTERVAL
    p = successes / n
    denominator = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denominator
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denominator
    return min(p, max(0.0, centre - half)), max(p, min(1.0, centre + half))


def rate(successes: int, n: int) -> float:
    """successes / n; nan for n = 0."""
    return successes / n if n else float("nan")


def bootstrap_interval(values, resamples: int = 2000, seed: int = 0, percentiles=(5.0, 95.0)) -> tuple[float, float]:
    """Percentile-bootstrap interval of the mean (default 90%); (nan, nan) for no values."""
    values = np.asarray(values, dtype=np.float64)
    if len(values) == 0:
        return NAN_INTERVAL
    index = np.random.default_rng(seed).integers(len(values), size=(resamples, len(values)))
    means = values[index].mean(axis=1)
    return float(np.percentile(means, percentiles[0])), float(np.percentile(means, percentiles[1]))


def mean(values) -> float:
    """Mean; nan for no values."""
    return float(np.mean(values)) if len(values) else float("nan")


def median(values) -> float:
    """Median; nan for no values."""
    return float(np.median(values)) if len(values) else float("nan")


def percentile(values, q: float) -> float:
    """q-th percentile (0-100, linear interpolation); nan for no values."""
    return float(np.percentile(values, q)) if len(values) else float("nan")


def none_if_nan(value):
    """A float statistic for JSON: nan (no data) -> None; tuples and lists element-wise, as lists."""
    if isinstance(value, tuple | list):
        return [none_if_nan(v) for v in value]
    if isinstance(value, float) and math.isnan(value):
        return None
    return value


def json_safe(value):
    """A summary for strict JSON: every non-finite float (no data) -> None, tuples -> lists, recursively."""
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
