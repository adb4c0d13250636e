"""reconstruction_node under malformed and extreme segmented frames, over DDS."""

import pytest
from node_conventions import (  # noqa: F401  collected here
    test_bad_parameter_values_are_rejected_at_run_time,
    test_clean_shutdown_on_sigint,
    test_parameters_are_declared_with_descriptors_and_ranges,
    test_parameters_read_at_start_up_refuse_a_change,
)
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
from robustness_nodes import run_against

from arm_benchmarks.robustness.cases.reconstruction import run_reconstruction_bad_inputs

from ros_helpers import require_reconstruction_params


@pytest.fixture(scope="module")
def run(frames, robustness_logs):
    publishers = {"publishers": lambda probe: probe.node.get_publishers_info_by_topic("/arm/meshes")}

    def cases(probe, process):
        return run_reconstruction_bad_inputs(probe, process, frames)

    return run_against("reconstruction", robustness_logs, cases, publishers, params=require_reconstruction_params())


def test_stays_alive_and_publishes_nothing_wrong(run):
    report = run["report"]
    assert report["subscribers_matched"]
    assert report["alive"] and not report["tracebacks"], report["tracebacks"]
    assert report["invalid_outputs"] == []
    assert report["cases_failed"] == [], [c for c in report["cases"] if not c["ok"]]


def test_every_frame_is_accounted_for(run):
    report = run["report"]
    counters = report["counters"]
    assert counters["frames_received"] == report["frames_sent"], counters
    assert counters["frames_rejected"] >= report["rejects_expected"], counters
    accounted = counters["frames_processed"] + counters["frames_rejected"] + counters["frames_dropped"]
    assert accounted == report["frames_sent"], (counters, report["cases"])


def test_rejections_are_logged_and_rate_limited(run):
    assert run["report"]["error_lines"] >= 1
    assert run["report"]["rate_limit_violations"] == []


def test_each_distinct_cause_is_logged(run):
    assert run["report"]["reasons_not_logged"] == []


def test_meshes_are_reliable_and_transient_local(run):
    ours = [p for p in run["publishers"] if p.node_name == "reconstruction_node"]
    assert ours and ours[0].qos_profile.reliability == ReliabilityPolicy.RELIABLE
    assert ours[0].qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
