import numpy as np

from arm_benchmarks.robustness.load import steady_growth_mb


def test_a_leak_grows_in_every_third_and_a_warm_up_step_does_not():
    rng = np.random.default_rng(0)
    t = np.arange(30.0)
    swings = rng.uniform(0.0, 120.0, len(t)) * (rng.random(len(t)) < 0.3)  # mid-frame peaks
    leak = 500.0 + 6.0 * t + swings  # 6 MB a sample: 60 MB a third
    warm_up = 500.0 + np.where(t < 12, 0.0, 70.0) + swings  # caches filled once, then flat
    flat = 500.0 + swings
    assert steady_growth_mb(list(leak)) > 40.0
    assert steady_growth_mb(list(warm_up)) < 5.0
    assert abs(steady_growth_mb(list(flat))) < 5.0
    assert steady_growth_mb([500.0, 510.0]) is None
