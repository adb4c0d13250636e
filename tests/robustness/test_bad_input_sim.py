"""sim_node under malformed joint trajectories, over DDS: it stays alive and its joint states stay valid."""

import pytest
from node_conventions import (  # noqa: F401  collected here
    test_bad_parameter_values_are_rejected_at_run_time,
    test_clean_shutdown_on_sigint,
    test_parameters_are_declared_with_descriptors_and_ranges,
    test_parameters_read_at_start_up_refuse_a_change,
)
from robustness_nodes import run_against

from arm_benchmarks.robustness.cases.sim import run_sim_bad_inputs


@pytest.fixture(scope="module")
def run(robustness_logs):
    params = {"n_objects": 3, "camera_rate_hz": 0.2, "width": 160, "height": 120}
    return run_against("sim", robustness_logs, run_sim_bad_inputs, params=params)


def test_stays_alive_and_joint_states_stay_valid(run):
    report = run["report"]
    assert report["subscribers_matched"]
    assert report["alive"] and not report["tracebacks"], report["tracebacks"]
    assert report["joint_states_checked"] > 50
    assert report["invalid_outputs"] == []
    assert report["cases_failed"] == [], [c for c in report["cases"] if not c["ok"]]


def test_rejections_are_logged_and_rate_limited(run):
    assert run["report"]["error_lines"] >= 1
    assert run["report"]["rate_limit_violations"] == []
    assert run["report"]["reasons_not_logged"] == []
