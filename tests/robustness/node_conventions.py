"""Convention checks every node's robustness module runs on its own module-scoped `run` fixture
(`run["conventions"]` from arm_benchmarks.robustness.parameters.convention_report, `run["exit_code"]`, `run["log"]`).
A test module imports these functions so that pytest collects them there."""


def test_parameters_are_declared_with_descriptors_and_ranges(run):
    c = run["conventions"]
    assert c["without_description"] == [] and c["numeric_without_range"] == []
    assert c["in_config_not_declared"] == [] and c["declared_not_in_config"] == []


def test_bad_parameter_values_are_rejected_at_run_time(run):
    assert run["conventions"]["bad_values_accepted_at_run_time"] == []


def test_parameters_read_at_start_up_refuse_a_change(run):
    """Every parameter is read once: declared read-only, so `ros2 param set` is refused."""
    c = run["conventions"]
    assert c["writable"] == [] and c.get("set_refused", True), c


def test_clean_shutdown_on_sigint(run):
    assert run["exit_code"] == 0, run["log"][-2000:]
