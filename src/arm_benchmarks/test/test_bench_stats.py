import json
import math

import pytest

from arm_benchmarks.bench_manip import plan_episodes
from arm_benchmarks.bench_stats import BINS, bin_label, summarise, wilson


def test_wilson_interval():
    p, lo, hi = wilson(8, 10)
    assert p == 0.8 and lo == pytest.approx(0.5408, abs=1e-3) and hi == pytest.approx(0.9314, abs=1e-3)
    assert wilson(0, 5)[1] == 0.0 and math.isnan(wilson(0, 0)[0])


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


def test_results_of_another_run_are_never_reused(tmp_path):
    from arm_benchmarks.bench_manip import load_done, run_key

    key, other = run_key({"steps": 200}), run_key({"steps": 300})
    assert key != other and key == run_key({"steps": 200})
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


def test_wilson_interval_contains_the_rate_at_the_ends():
    for k, n in [(0, 1), (0, 7), (3, 3), (11, 11)]:
        p, lo, hi = wilson(k, n)
        assert lo <= p <= hi
