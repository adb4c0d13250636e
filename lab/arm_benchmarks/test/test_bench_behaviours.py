"""bench_behaviours runs the suite's repeated-run behaviours every time and reports how often each held."""

import json

import arm_core.repeated_runs
from arm_benchmarks.bench_behaviours import main, suite_failure_chance

BEHAVIOURS = """
from arm_core.repeated_runs import holds_repeatedly


def test_holds_on_even_runs():
    held, outcomes = holds_repeatedly(lambda run: (run % 2 == 0, run))


def test_two_behaviours():
    holds_repeatedly(lambda run: (True, run))
    holds_repeatedly(lambda run: (run == 0, run))
"""


def test_every_run_is_made_and_each_behaviour_reported_and_a_rerun_resumes(tmp_path):
    tests = tmp_path / "test_fake_behaviours.py"
    tests.write_text(BEHAVIOURS)
    original = arm_core.repeated_runs.holds_repeatedly
    out = tmp_path / "out"
    assert main([str(tests), "--runs", "4", "--out", str(out)]) == 0
    assert arm_core.repeated_runs.holds_repeatedly is original, "the suite's helper is restored"
    behaviours = json.loads((out / "summary.json").read_text())["behaviours"]
    by_test = {name.split("::")[-1]: b for name, b in behaviours.items()}
    assert by_test["test_holds_on_even_runs"]["held"] == 2 and by_test["test_holds_on_even_runs"]["runs"] == 4
    assert by_test["test_two_behaviours"]["hold_rate"] == 1.0 and by_test["test_two_behaviours #2"]["held"] == 1
    assert "test_holds_on_even_runs" in (out / "report.md").read_text()
    lines = (out / "runs.jsonl").read_text().splitlines()
    assert main([str(tests), "--runs", "4", "--out", str(out)]) == 0
    assert (out / "runs.jsonl").read_text().splitlines() == lines, "finished tests are not run again"


def test_the_suite_fails_when_fewer_than_the_needed_runs_hold():
    assert suite_failure_chance(1.0) == 0.0 and suite_failure_chance(0.0) == 1.0
    assert abs(suite_failure_chance(0.5, runs=3, needed=2) - 0.5) < 1e-12
    assert suite_failure_chance(0.7) < 0.012, "the suite's rule at the lowest measured rate"
