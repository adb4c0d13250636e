import json

import pytest

from arm_benchmarks import manip_pool

DESIGN = {"episodes": 6, "seed": 0, "tasks": ["grasp", "push"], "bins": ["1.0"], "objects": "procedural"}
DESIGN |= {"observe_period_s": 0.1}


def _run(folder, key, successes, only_tasks=None, **changes):
    """A bench_manip output: rows per (episode, task, method) with the given success, plus a stale row."""
    settings = DESIGN | {"methods": ["ground-truth", "arm"], "run_key": key} | changes
    if only_tasks:
        settings["only_tasks"] = only_tasks
    folder.mkdir()
    (folder / "summary.json").write_text(json.dumps({"settings": settings}))
    rows = [
        {"episode": i, "task": task, "bin": "1.0", "method": m, "success": successes[task], "run_key": key}
        for i, task in enumerate(["grasp", "push"] * 3)
        for m in settings["methods"]
    ]
    rows.append({"episode": 0, "task": "grasp", "bin": "1.0", "method": "arm", "success": True, "run_key": "old"})
    (folder / "episodes.jsonl").write_text("\n".join(json.dumps(r) for r in rows) + "\n")
    return folder


def test_a_partial_run_replaces_its_tasks_of_the_full_run(tmp_path):
    full = _run(tmp_path / "full", "k1", {"grasp": False, "push": False})
    push = _run(tmp_path / "push", "k2", {"grasp": False, "push": True}, only_tasks=["push"])
    out = tmp_path / "pooled"
    assert manip_pool.main([str(full), str(push), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    arm = summary["methods"]["arm"]
    assert arm["by_task"] == {"grasp": 0.0, "push": 1.0}, "grasp from the full run, push from the partial one"
    assert arm["n"] == 6, "rows of other run keys do not count"
    assert set(summary["settings"]["pooled_from"]) == {"grasp", "push"}
    assert "closed loop" in (out / "report.md").read_text(), "the execution is part of the design"


def test_runs_of_another_design_or_covering_a_task_twice_are_refused(tmp_path):
    full = _run(tmp_path / "full", "k1", {"grasp": True, "push": True})
    other_seed = _run(tmp_path / "seed1", "k2", {"grasp": True, "push": True}, only_tasks=["push"], seed=1)
    with pytest.raises(ValueError, match="seed"):
        manip_pool.pool([full, other_seed])
    open_loop = _run(tmp_path / "open", "k5", {"grasp": True, "push": True}, only_tasks=["push"], observe_period_s=0.0)
    with pytest.raises(ValueError, match="observe_period_s"):
        manip_pool.pool([full, open_loop])
    a = _run(tmp_path / "a", "k3", {"grasp": True, "push": True}, only_tasks=["push"])
    b = _run(tmp_path / "b", "k4", {"grasp": True, "push": True}, only_tasks=["push"])
    with pytest.raises(ValueError, match="both"):
        manip_pool.pool([full, a, b])
    with pytest.raises(ValueError, match="grasp"):
        manip_pool.pool([a])
    with pytest.raises(ValueError, match="not a bench_manip output"):
        manip_pool.pool([tmp_path])
