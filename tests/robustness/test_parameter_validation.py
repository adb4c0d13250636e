"""Every node refuses invalid parameters at start-up with a clear message naming itself and the
parameter, and exit code 2 (no traceback)."""

import pytest

from arm_benchmarks.robustness.cases.parameters import PARAMETER_CASES, run_parameter_validation

from ros_helpers import require_built


@pytest.fixture(scope="module")
def outcomes(robustness_logs):
    require_built(*sorted({key for key, _, _, _ in PARAMETER_CASES}))
    return {(r["node"], r["parameter"]): r for r in run_parameter_validation(robustness_logs)}


@pytest.mark.parametrize("case", PARAMETER_CASES, ids=[f"{k}-{n}-{kind}" for k, n, _, kind in PARAMETER_CASES])
def test_invalid_parameter_is_refused_at_start_up(outcomes, case):
    key, name, value, kind = case
    outcome = outcomes[(key, name)]
    assert outcome["exit_code"] is not None, f"{key} kept running with {name}={value!r}:\n{outcome['log_tail']}"
    assert outcome["ok"], outcome
