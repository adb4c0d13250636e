"""The full graph fed by a 30 Hz camera (a looping bag): latest-frame processing, bounded memory, no
crash; then kill -9 of the reconstruction node mid-run and its restart."""

import json

import pytest

from arm_benchmarks.robustness.bags import write_camera_bag
from arm_benchmarks.robustness.frames import render_frames
from arm_benchmarks.robustness.load import run_fault, run_load, start_graph, stop_graph
from arm_benchmarks.robustness.probe import Probe

from ros_helpers import require_built, require_reconstruction_params

LOAD_S = 20.0
CAMERA_HZ = 30.0
FAST_PLANNER = {"steps": 5, "settle_s": 0.0, "nthread": 1, "execution": "plan_only"}
# The soak waits for the planner's scene history to fill (robustness.load.warmup_mesh_arrays); this
# short run measures from the third array, the history filling within it (about 0.7 MB an array).
WARMUP_MESHES = 3


@pytest.fixture(scope="module")
def run(robustness_logs):
    require_built("segmentation", "reconstruction", "planner", "replay")
    params = require_reconstruction_params()
    bag = robustness_logs / "camera_30hz"
    write_camera_bag(bag, render_frames(5, seed=3, count=3), CAMERA_HZ)
    log_dir = robustness_logs / "graph"
    graph = start_graph(log_dir, bag, params, planner_params=FAST_PLANNER)
    probe = Probe()
    try:
        load = run_load(probe, graph, LOAD_S, warmup_meshes=WARMUP_MESHES)
        fault = run_fault(probe, graph, load.pop("watch"), params, log_dir / "reconstruction_restarted.log")
    finally:
        probe.close()
        stopped = stop_graph(graph)
    return {"load": load, "fault": fault, "stopped": stopped}


def test_camera_runs_near_30_hz_into_the_full_graph_without_a_crash(run):
    load = run["load"]
    assert load["warm"], "no meshes came out of the graph"
    assert all(load["alive"].values()), load["alive"]
    assert load["rates_hz"]["camera"] > 0.6 * CAMERA_HZ, load["rates_hz"]
    assert load["rates_hz"]["segmentation"] > 0


def test_latest_frame_processing_keeps_the_lag_bounded(run):
    lag = run["load"]["lag"]["segmentation"]
    assert lag["outputs"] >= 5, lag
    # a queue would add (30 Hz x processing time - 1) frames of lag every second
    assert lag["last_third_median_s"] - lag["first_third_median_s"] < 1.0, lag
    assert lag["max_s"] < 5.0, lag
    diagnostics = run["load"]["diagnostics"]["segmentation"]
    received = float(diagnostics.get("messages_received", 0))  # rgb, depth, camera_info and pose
    published = float(diagnostics.get("frames_published", 0))
    # a 30 Hz camera outruns segmentation: latest-frame processing skips the frames it cannot keep up
    # with (a queue would segment every one of them, late)
    assert 0 < published < received / 4, diagnostics


def test_no_node_leaks_memory_during_the_load_run(run):
    """A leak grows what a node holds from frame to frame: from the first third of the run to the
    middle one and again to the last (robustness.load.steady_growth_mb, each step the smaller of the
    lowest and the median samples' change). Samples taken mid-frame swing by 100 MB with the frame
    being reconstructed, and the first frames after the warm-up still fill caches once (one run on
    another CPU: reconstruction_node +53 MB floor, +70 MB median over 20 s, flat after it), so
    neither a single step nor a single sample counts. Slow leaks are the soak's to find
    (bench_robustness --duration-s 600)."""
    memory = run["load"]["memory"]
    steady = {k: v["steady_growth_mb"] for k, v in memory.items()}
    assert all(v is not None for v in steady.values()), f"nodes without memory samples: {memory}"
    assert all(v < 25.0 for v in steady.values()), f"steady growth per third of the run (MB) {steady}, {memory}"


def test_kill9_of_reconstruction_planner_keeps_meshes_and_pipeline_resumes(run):
    fault = run["fault"]
    assert fault["killed_exit_code"] == -9
    assert all(fault["others_alive_during_outage"].values()), fault
    # the planner keeps the last meshes it had (a mesh message in flight at the kill may still update them)
    assert fault["planner_objects_before"] > 0 and fault["planner_objects_during_outage"] > 0, fault
    assert fault["segmentation_kept_publishing"], fault
    assert fault["goal_during_outage"].get("planned"), fault["goal_during_outage"]
    fresh = fault["fresh_reader"]
    if not fault["resumed"] and fresh["published"] > 0 and fresh["received"] == 0:
        # segmentation_node keeps publishing, yet no subscriber, not even a new one, gets a frame: the
        # publisher itself is wedged by the killed reader, a Fast DDS 2.14 fault (eProsima/Fast-DDS#5469)
        pytest.xfail(f"Fast DDS writer wedged after kill -9 of its reader: {json.dumps(fault, default=str)}")
    assert fault["resumed"], json.dumps(fault, indent=1, default=str)
    assert all(fault["alive_after"].values()), fault["alive_after"]


@pytest.mark.parametrize("key", ["replay", "segmentation", "planner"])
def test_graph_shuts_down_cleanly_without_tracebacks(run, key):
    outcome = run["stopped"][key]
    assert outcome["exit_code"] == 0 and not outcome["tracebacks"], outcome


def test_reconstruction_shuts_down_cleanly_while_busy(run):
    """SIGINT while a frame is being reconstructed: the worker drops its publish instead of raising."""
    outcome = run["stopped"]["reconstruction"]
    assert outcome["exit_code"] == 0 and not outcome["tracebacks"], outcome
