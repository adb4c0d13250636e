from arm_benchmarks.bench_demo import outcome, parse_seeds


def test_seed_ranges_and_lists():
    assert parse_seeds("1-10") == list(range(1, 11))
    assert parse_seeds("3,5-6") == [3, 5, 6]


def test_outcomes_of_a_demo_summary():
    assert outcome({"task": {"target_id": 4, "success_in_sim": True}}) == "done"
    assert outcome({"task": {"target_id": 4, "success_in_sim": False}}) == "not done"
    assert outcome({"task": {"target_id": None, "why": "no reconstructed object within reach"}}) == "no target"
    assert outcome({"task": {"error": "planning timed out"}}) == "error"
    assert outcome({"seed": 3, "error": "demo exited 1 without a summary"}) == "error"
