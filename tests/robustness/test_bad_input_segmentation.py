"""segmentation_node under malformed and extreme camera input, over DDS, with remapped topics."""

import pytest
from node_conventions import (  # noqa: F401  collected here
    test_bad_parameter_values_are_rejected_at_run_time,
    test_clean_shutdown_on_sigint,
    test_parameters_are_declared_with_descriptors_and_ranges,
    test_parameters_read_at_start_up_refuse_a_change,
)
from rclpy.qos import ReliabilityPolicy
from robustness_nodes import run_against

from arm_benchmarks.robustness.cases.segmentation import run_segmentation_bad_inputs
from arm_benchmarks.robustness.messages import CAMERA_TOPICS

PREFIX = "/robustness/"


@pytest.fixture(scope="module")
def run(frames, robustness_logs):
    remaps = {t: PREFIX + t for t in CAMERA_TOPICS}
    remaps["arm/segmented_frame"] = PREFIX + "segmented_frame"

    def cases(probe, process):
        return run_segmentation_bad_inputs(probe, process, frames, PREFIX + "segmented_frame", input_prefix=PREFIX)

    image = PREFIX + "camera/color/image_raw"
    subscriptions = {"subscriptions": lambda probe: probe.node.get_subscriptions_info_by_topic(image)}
    params = {"image_reliability": "reliable"}
    return run_against("segmentation", robustness_logs, cases, subscriptions, params=params, remaps=remaps)


def test_stays_alive_and_publishes_nothing_wrong(run):
    report = run["report"]
    assert report["subscribers_matched"], "the node never subscribed to the remapped camera topics"
    assert report["alive"] and not report["tracebacks"], report["tracebacks"]
    assert report["invalid_outputs"] == []
    assert report["cases_failed"] == [], [c for c in report["cases"] if not c["ok"]]
    assert report["inputs_tried"] >= 20


def test_rejections_are_logged_and_rate_limited(run):
    report = run["report"]
    assert report["error_lines"] >= 1
    assert report["rate_limit_violations"] == []


def test_each_distinct_cause_is_logged(run):
    assert run["report"]["reasons_not_logged"] == []


def test_image_qos_reliability_is_the_parameter(run):
    ours = [s for s in run["subscriptions"] if s.node_name == "segmentation_node"]
    assert ours, "no subscription on the remapped rgb topic"
    assert ours[0].qos_profile.reliability == ReliabilityPolicy.RELIABLE
