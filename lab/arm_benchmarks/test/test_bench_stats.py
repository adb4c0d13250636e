import json
import math

from arm_benchmarks.bench_manip import GROUND_TRUTH, load_done, plan_episodes, result_key
from arm_benchmarks.bench_stats import BINS, bin_label, summarise, write_report


def test_bins_match_the_paper():
    labels = [bin_label(b) for b in BINS]
    assert len(labels) == 11 and labels[0] == "0.0-0.1" and labels[-2] == "0.9-1.0" and labels[-1] == "1.0"


def test_episodes_cycle_tasks_and_bins():
    episodes = plan_episodes(66, ["grasp", "push", "rearrange"], range(len(BINS)), 0)
    combos = {(e.task, e.bin_index) for e in episodes[:33]}
    assert len(combos) == 33 and len({e.seed for e in episodes}) == 66
    two_bins = plan_episodes(12, ["grasp", "push", "rearrange"], [1, 10], 0)
    assert {e.bin_index for e in two_bins} == {1, 10} and len({(e.task, e.bin_index) for e in two_bins[:6]}) == 6


def test_summary_layout_and_excluded_rows():
    rows = [
        {"method": "arm", "task": "grasp", "bin": "1.0", "success": True},
        {"method": "arm", "task": "push", "bin": "0.1-0.2", "success": False},
        {"method": "arm", "task": "push", "bin": "0.1-0.2", "success": False, "skipped": "no scene"},
        {"method": "baseline", "task": "grasp", "bin": "1.0", "success": False, "unavailable": "no checkpoint"},
    ]
    summary = summarise(rows, ["arm", "baseline"], ["grasp", "push"], BINS, 3)
    arm = summary["methods"]["arm"]
    assert summary["episodes"] == 3 and arm["n"] == 2 and arm["success"] == 0.5
    assert arm["by_task"] == {"grasp": 1.0, "push": 0.0}
    assert arm["by_visibility"]["1.0"] == 1.0 and math.isnan(arm["by_visibility"]["0.5-0.6"])
    assert summary["methods"]["baseline"]["unavailable"] == ["no checkpoint"]


def test_episodes_ground_truth_refuses_as_infeasible_are_left_out_of_the_feasible_rate(tmp_path):
    rows = [
        {"episode": 0, "method": GROUND_TRUTH, "task": "grasp", "bin": "1.0", "success": True},
        {"episode": 0, "method": "arm", "task": "grasp", "bin": "1.0", "success": True},
        {"episode": 1, "method": GROUND_TRUTH, "task": "grasp", "bin": "1.0", "success": False, "infeasible": True},
        {"episode": 1, "method": "arm", "task": "grasp", "bin": "1.0", "success": False},
        {"episode": 2, "method": GROUND_TRUTH, "task": "grasp", "bin": "1.0", "success": False},
        {"episode": 2, "method": "arm", "task": "grasp", "bin": "1.0", "success": True},
    ]
    summary = summarise(rows, [GROUND_TRUTH, "arm"], ["grasp"], BINS, 3)
    truth, arm = summary["methods"][GROUND_TRUTH], summary["methods"]["arm"]
    assert summary["infeasible_episodes"] == [1]
    assert (
        truth["n"] == 3 and truth["success"] == 1 / 3 and truth["feasible_n"] == 2 and truth["feasible_success"] == 0.5
    )
    assert arm["feasible_n"] == 2 and arm["feasible_success"] == 1.0
    assert summary["targets"]["ground_truth_feasible_success"] == 0.5
    write_report(summary, tmp_path)
    assert "cannot do at all" in (tmp_path / "report.md").read_text()


def test_results_of_another_run_are_never_reused(tmp_path):
    key, other = result_key({"steps": 200}), result_key({"steps": 300})
    assert key != other and key == result_key({"steps": 200})
    log = tmp_path / "episodes.jsonl"
    rows = [
        {"episode": 0, "method": "arm", "success": True, "run_key": key},
        {"episode": 1, "method": "arm", "success": True, "run_key": other},
        {"episode": 2, "method": "arm", "success": True},
    ]
    log.write_text("".join(json.dumps(row) + "\n" for row in rows))
    done = load_done(log, key)
    assert list(done) == [(0, "arm")]
    assert len(log.read_text().splitlines()) == 1
    assert len((tmp_path / "episodes.stale.jsonl").read_text().splitlines()) == 2


def test_older_ground_truth_rows_are_read_under_the_current_name(tmp_path):
    log = tmp_path / "episodes.jsonl"
    log.write_text(json.dumps({"episode": 0, "method": "ground_truth", "success": True, "run_key": "k"}) + "\n")
    assert list(load_done(log, "k")) == [(0, GROUND_TRUTH)] and GROUND_TRUTH == "ground-truth"


def test_robust_success_is_the_share_of_perturbed_executions_and_the_report_shows_it(tmp_path):
    rows = [
        {"episode": 0, "method": "arm", "task": "grasp", "bin": "1.0", "success": True, "robust": [True, True, False]},
        {"episode": 1, "method": "arm", "task": "push", "bin": "1.0", "success": True, "robust": [False] * 3},
        {"episode": 2, "method": "arm", "task": "push", "bin": "0.1-0.2", "success": False},  # no plan
    ]
    summary = summarise(rows, ["arm"], ["grasp", "push"], BINS, 3, robust_worlds=3)
    arm = summary["methods"]["arm"]
    assert arm["robust_n"] == 9 and math.isclose(arm["robust_success"], 2 / 9)
    assert math.isclose(arm["robust_by_task"]["grasp"], 2 / 3) and arm["robust_by_task"]["push"] == 0.0
    assert arm["robust_by_visibility_n"]["1.0"] == 6 and arm["robust_success_ci90"][0] < 2 / 9
    summary["settings"] = {}
    write_report(summary, tmp_path)
    assert "## Robust success" in (tmp_path / "report.md").read_text()
