"""plan_node under degenerate meshes, unknown targets and tasks, bad joint states and goals, over DDS."""

import pytest
from node_conventions import (  # noqa: F401  collected here
    test_bad_parameter_values_are_rejected_at_run_time,
    test_clean_shutdown_on_sigint,
    test_parameters_are_declared_with_descriptors_and_ranges,
    test_parameters_read_at_start_up_refuse_a_change,
)
from rclpy.qos import DurabilityPolicy
from robustness_nodes import run_against

from arm_benchmarks.robustness.cases.planner import run_planner_bad_inputs

# the trajectories go out on the topic, where the harness inspects them
FAST_PLANNER = {"steps": 5, "settle_s": 0.0, "nthread": 1, "execution": "stream", "controller_interface": "topic"}


@pytest.fixture(scope="module")
def run(robustness_logs):
    subscriptions = {"subscriptions": lambda probe: probe.node.get_subscriptions_info_by_topic("/arm/meshes")}
    return run_against("planner", robustness_logs, run_planner_bad_inputs, subscriptions, params=FAST_PLANNER)


def test_stays_alive_answers_every_goal_and_publishes_nothing_wrong(run):
    report = run["report"]
    assert report["action_server_ready"]
    assert report["alive"] and not report["tracebacks"], report["tracebacks"]
    assert report["invalid_outputs"] == []


def test_every_case_is_handled_as_expected(run):
    """Including a 1e6 m box: left out of the twin (max_object_size_m), so its goal is refused."""
    assert [c["name"] for c in run["report"]["cases"] if not c["ok"]] == []


def test_only_planned_goals_publish_trajectories(run):
    report = run["report"]
    assert report["trajectories_published"] == report["goals_planned"]


def test_refusals_are_logged_and_rate_limited(run):
    assert run["report"]["error_lines"] >= 1
    assert run["report"]["rate_limit_violations"] == []


def test_meshes_subscription_is_transient_local(run):
    ours = [s for s in run["subscriptions"] if s.node_name == "plan_node"]
    assert ours and ours[0].qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
