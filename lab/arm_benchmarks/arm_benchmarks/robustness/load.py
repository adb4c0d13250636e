"""Load and fault runs of the full graph (camera replay -> segmentation -> reconstruction -> planner),
measured from outside over DDS: achieved camera rate, per-stage output rates, lag of each output
behind the newest camera frame (latest-frame processing keeps it bounded; a queue makes it grow),
memory of every node process, and survival of a kill -9 of the reconstruction node."""

from __future__ import annotations

import os
import signal
import time

import numpy as np
from rclpy.action import ActionClient
from sensor_msgs.msg import CameraInfo

from arm_benchmarks.robustness.logs import tracebacks
from arm_benchmarks.robustness.messages import stamp_of
from arm_interfaces.action import Manipulate
from arm_interfaces.msg import ReconstructedObjectArray, SegmentedFrame
from arm_planner.node_config import PlanNodeConfig
from arm_ros.common import latched_qos, sensor_qos
from arm_ros.processes import NodeProcess

GRAPH_ORDER = ("replay", "segmentation", "reconstruction", "planner")
# Fast DDS 2.14's shared-memory transport can leave a port of a kill -9'd process locked, and a
# process restarted in its place then matches its peers but receives nothing (eProsima/Fast-DDS
# #5053, #5469). A respawned node alone on UDP still missed its frames in about 1 of 4 fresh-clone
# runs, so the whole graph talks over UDP only.
GRAPH_DDS_ENV = {"FASTDDS_BUILTIN_TRANSPORTS": "UDPv4"}


def start_graph(
    log_dir,
    bag,
    recon_params: dict,
    image_reliability: str = "reliable",
    planner_params: dict | None = None,
    replay_params: dict | None = None,
) -> dict[str, NodeProcess]:
    """The full graph fed by a looping camera bag (replayed at its own rate)."""

    def node(name: str, **kwargs) -> NodeProcess:
        return NodeProcess(name, log_dir / f"{name}.log", env=GRAPH_DDS_ENV, **kwargs)

    graph = {
        "segmentation": node("segmentation", params={"image_reliability": image_reliability}),
        "reconstruction": node("reconstruction", params=recon_params),
        "planner": node("planner", params=planner_params or {}),
    }
    replay = {"loop": True, "wait_subscribers_s": 60.0, "linger_s": 0.0, **(replay_params or {})}
    graph["replay"] = node("replay", args=(str(bag),), params=replay)
    return graph


def stop_graph(graph: dict[str, NodeProcess]) -> dict[str, dict]:
    """SIGINT every node (the feeder first); exit codes and tracebacks per node."""
    out = {}
    for key in GRAPH_ORDER:
        if key in graph:
            code = graph[key].stop(signal.SIGINT)
            out[key] = {"exit_code": code, "tracebacks": tracebacks(graph[key].log())}
    return out


class GraphWatch:
    """Probe subscriptions on the graph's camera and outputs, with lag bookkeeping."""

    def __init__(self, probe):
        self.probe = probe
        self.latest_camera_s = float("nan")
        self.lags = {"segmentation": [], "reconstruction": []}

        def on_camera(msg):
            self.latest_camera_s = stamp_of(msg)

        def lag(stage):
            def on_output(msg):
                self.lags[stage].append((time.monotonic(), self.latest_camera_s - stamp_of(msg)))

            return on_output

        self.camera = probe.record(
            CameraInfo, "camera/camera_info", sensor_qos("reliable", 10), keep=10, on_message=on_camera
        )
        self.frames = probe.record(SegmentedFrame, "arm/segmented_frame", 10, keep=2, on_message=lag("segmentation"))
        self.meshes = probe.record(
            ReconstructedObjectArray, "arm/meshes", latched_qos(), keep=20, on_message=lag("reconstruction")
        )
        probe.watch_diagnostics()

    def totals(self) -> dict[str, int]:
        """Messages received so far per stream (the deques keep only the last few)."""
        with self.probe.lock:
            return {"camera": self.camera.total, "segmentation": self.frames.total, "reconstruction": self.meshes.total}

    def last_meshes(self):
        with self.probe.lock:
            return self.meshes[-1] if self.meshes else None


def steady_growth_mb(series: list[float]) -> float | None:
    """Growth (MB) that a leak shows and a warm-up does not: the series is cut in thirds, each third
    summarised by its lowest and its median sample, and the growth from one third to the next is the
    smaller of the two changes; a leak grows from the first third to the second and again to the
    last, a warm-up step or a one-off allocation in one of them only. The smaller of the two steps."""
    if len(series) < 3:
        return None
    thirds = np.array_split(np.asarray(series, dtype=np.float64), 3)
    floors = [float(t.min()) for t in thirds]
    medians = [float(np.median(t)) for t in thirds]
    steps = [min(floors[i + 1] - floors[i], medians[i + 1] - medians[i]) for i in range(2)]
    return round(min(steps), 1)


def machine_steal_s() -> float:
    """CPU seconds the hypervisor has given to other guests (/proc/stat's steal column, all CPUs)."""
    try:
        with open("/proc/stat") as stat:
            fields = stat.readline().split()
        return int(fields[8]) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return float("nan")


def rates_by_window(samples: list[dict], stream: str, window_s: float = 60.0) -> list[float]:
    """Messages per second of `stream` in each whole window_s of a run, from the samples' running
    totals (count_<stream> at t_s seconds), interpolated at the windows' edges."""
    if len(samples) < 2:
        return []
    t = np.array([s["t_s"] for s in samples], dtype=np.float64)
    count = np.array([s[f"count_{stream}"] for s in samples], dtype=np.float64)
    edges = np.arange(t[0], t[-1] + 1e-9, window_s)
    if len(edges) < 2:
        return []
    return [round(float(r), 2) for r in np.diff(np.interp(edges, t, count)) / window_s]


def medians_by_window(samples: list[dict], key: str, window_s: float = 60.0) -> list[float]:
    """Median of the sampled value `key` in each whole window_s of a run (NaN samples left out)."""
    t = np.array([s["t_s"] for s in samples], dtype=np.float64)
    value = np.array([s[key] for s in samples], dtype=np.float64)
    out = []
    for start in np.arange(t[0], t[-1] - window_s + 1e-9, window_s) if len(t) else []:
        inside = (t >= start) & (t < start + window_s) & np.isfinite(value)
        out.append(round(float(np.median(value[inside])), 1) if np.any(inside) else float("nan"))
    return out


def rate_against_first_window(rates: list[float], tolerance: float = 0.1) -> dict | None:
    """The first window's rate against the later ones: their median and lowest, and the share of
    them within `tolerance` (relative) of the first."""
    if len(rates) < 2 or rates[0] <= 0:
        return None
    first, later = rates[0], np.asarray(rates[1:])
    return {
        "first_hz": first,
        "later_median_hz": round(float(np.median(later)), 2),
        "later_lowest_hz": round(float(later.min()), 2),
        "later_within_tolerance": round(float(np.mean(np.abs(later / first - 1.0) <= tolerance)), 2),
    }


def warmup_mesh_arrays() -> int:
    """Mesh arrays the graph publishes before its memory is measured: until the planner's scene
    history (PlanNodeConfig.scene_history arrays, about 0.7 MB each for six objects) is full, and at
    least 3 (allocator pools and caches fill during the first frames). Filling a bounded buffer is
    warm-up, not growth."""
    return max(3, PlanNodeConfig().scene_history)


def run_load(
    probe,
    graph: dict[str, NodeProcess],
    duration_s: float,
    warmup_meshes: int | None = None,
    warmup_timeout_s: float = 240.0,
    sample_period_s: float = 1.0,
    progress=None,
) -> dict:
    """Run the graph for duration_s once `warmup_meshes` mesh arrays came out (None:
    warmup_mesh_arrays()); sample memory and rates. Memory of the warm-up is kept apart
    (`at_first_meshes_mb`) from the growth during the measured run."""
    warmup_meshes = warmup_mesh_arrays() if warmup_meshes is None else warmup_meshes
    watch = GraphWatch(probe)
    started = time.monotonic()
    warm = probe.wait_until(lambda: watch.totals()["reconstruction"] > 0, warmup_timeout_s, poll_s=0.2)
    first_meshes_rss = {k: round(p.rss_mb(), 1) for k, p in graph.items()}
    warm = warm and probe.wait_until(
        lambda: watch.totals()["reconstruction"] >= warmup_meshes, warmup_timeout_s, poll_s=0.2
    )
    warmup_s = time.monotonic() - started
    samples = []
    begin = time.monotonic()
    first_totals = watch.totals()
    while time.monotonic() - begin < duration_s:
        samples.append(
            {
                "t_s": round(time.monotonic() - begin, 2),
                **{f"rss_mb_{k}": round(p.rss_mb(), 1) for k, p in graph.items()},
                **{f"count_cpu_s_{k}": round(p.cpu_s(), 2) for k, p in graph.items()},
                "count_steal_s": machine_steal_s(),
                # the segmentation node's own counters (its diagnostics, once a second): the messages its
                # executor took from DDS, and how long its last frame took from decoding to publishing
                "count_segmentation_messages_taken": probe.diagnostic_number("segmentation_node", "messages_received"),
                "segmentation_frame_ms": probe.diagnostic_number("segmentation_node", "last_latency_ms"),
                **{f"count_{k}": v for k, v in watch.totals().items()},
            }
        )
        if progress is not None:
            progress(samples[-1])
        time.sleep(sample_period_s)
    elapsed = time.monotonic() - begin
    totals = watch.totals()
    rates = {k: round((totals[k] - first_totals[k]) / elapsed, 2) for k in totals}
    memory = {}
    for key in graph:
        series = [s[f"rss_mb_{key}"] for s in samples if np.isfinite(s[f"rss_mb_{key}"])]
        third = max(1, len(series) // 3)
        memory[key] = {
            "at_first_meshes_mb": first_meshes_rss[key],
            "start_mb": series[0] if series else None,
            "end_mb": series[-1] if series else None,
            "growth_mb": round(series[-1] - series[0], 1) if series else None,
            "max_growth_mb": round(max(series) - series[0], 1) if series else None,
            # median of the last third minus the first third: growth without single-frame spikes
            "trend_growth_mb": round(float(np.median(series[-third:]) - np.median(series[:third])), 1)
            if series
            else None,
            # lowest of the last third minus lowest of the first third: what stays between frames (a
            # leak raises it; a frame's transient allocations, returned to the system, do not)
            "floor_growth_mb": round(float(min(series[-third:]) - min(series[:third])), 1) if series else None,
            "steady_growth_mb": steady_growth_mb(series),
        }
    lag = {}
    for stage, values in watch.lags.items():
        in_run = [v for t, v in values if t >= begin and np.isfinite(v)]
        third = max(1, len(in_run) // 3)
        lag[stage] = {
            "outputs": len(in_run),
            "median_s": round(float(np.median(in_run)), 3) if in_run else None,
            "max_s": round(float(np.max(in_run)), 3) if in_run else None,
            "first_third_median_s": round(float(np.median(in_run[:third])), 3) if in_run else None,
            "last_third_median_s": round(float(np.median(in_run[-third:])), 3) if in_run else None,
        }
    diagnostics = {
        k: probe.diagnostic(name)
        for k, name in [
            ("segmentation", "segmentation_node"),
            ("reconstruction", "reconstruction_node"),
            ("planner", "plan_node"),
            ("replay", "bag_replayer"),
        ]
    }
    return {
        "warm": warm,
        "warmup_s": round(warmup_s, 1),
        "warmup_meshes": warmup_meshes,
        "duration_s": round(elapsed, 1),
        "rates_hz": rates,
        "rates_by_minute_hz": {k: rates_by_window(samples, k) for k in totals},
        "segmentation_messages_taken_by_minute_hz": rates_by_window(samples, "segmentation_messages_taken"),
        "segmentation_frame_ms_by_minute": medians_by_window(samples, "segmentation_frame_ms"),
        # CPU seconds per second, per node, and the CPU the hypervisor took from this machine
        "cpu_by_minute": {
            **{k: rates_by_window(samples, f"cpu_s_{k}") for k in graph},
            "stolen_by_hypervisor": rates_by_window(samples, "steal_s"),
        },
        "lag": lag,
        "memory": memory,
        "samples": samples,
        "alive": {k: p.alive() for k, p in graph.items()},
        "diagnostics": {k: {kk: vv for kk, vv in v.items() if not kk.startswith("_")} for k, v in diagnostics.items()},
        "watch": watch,
    }


def run_fault(
    probe,
    graph: dict[str, NodeProcess],
    watch: GraphWatch,
    recon_params: dict,
    restart_log,
    outage_s: float = 5.0,
    resume_timeout_s: float = 180.0,
    goal_timeout_s: float = 120.0,
) -> dict:
    """kill -9 the reconstruction node; during the outage the planner must keep the last meshes and
    still plan on them; after a restart (log in restart_log, GRAPH_DDS_ENV) new meshes must flow again."""
    planner_objects_before = probe.diagnostic_number("plan_node", "twin_objects", 0)
    frames_before = watch.totals()["segmentation"]
    graph["reconstruction"].kill9()
    killed_at = time.monotonic()
    killed_code = graph["reconstruction"].process.returncode
    probe.wait_until(lambda: False, outage_s)
    planner_objects_during = probe.diagnostic_number("plan_node", "twin_objects", 0)
    others_alive = {k: p.alive() for k, p in graph.items() if k != "reconstruction"}
    segmentation_kept_running = watch.totals()["segmentation"] > frames_before

    goal_result = {"sent": False}
    # the planner's own objects: a message in flight at the kill may have replaced the scene, and the
    # planner leaves implausible objects (max_object_size_m) out of its twin
    planner_ids = [int(i) for i in probe.diagnostic("plan_node").get("twin_object_ids", "").split()]
    if planner_ids:
        action = ActionClient(probe.node, Manipulate, "arm/manipulate")
        if action.wait_for_server(timeout_sec=30.0):
            goal = Manipulate.Goal(task=Manipulate.Goal.TASK_GRASP, target_id=planner_ids[0])
            handle_future = probe.in_executor(lambda: action.send_goal_async(goal))
            probe.wait_until(handle_future.done, 30.0)
            goal_result = {"sent": True, "target_id": planner_ids[0]}
            if handle_future.done() and handle_future.result().accepted:
                result_future = probe.in_executor(handle_future.result().get_result_async)
                probe.wait_until(result_future.done, goal_timeout_s)
                if result_future.done():
                    result = result_future.result()
                    goal_result.update(planned=result.status == 4, message=result.result.message)
    newest = watch.last_meshes()  # anything the killed node had in flight has arrived by now
    before_stamp = stamp_of(newest) if newest is not None else float("-inf")
    frames_at_restart = watch.totals()["segmentation"]
    graph["reconstruction"] = NodeProcess("reconstruction", restart_log, params=recon_params, env=GRAPH_DDS_ENV)
    restarted_at = time.monotonic()
    resumed = probe.wait_until(
        lambda: (m := watch.last_meshes()) is not None and stamp_of(m) > before_stamp, resume_timeout_s, poll_s=0.2
    )
    restarted = probe.diagnostic("reconstruction_node")
    segmented_at = [t for t, _ in watch.lags["segmentation"]]
    return {
        "killed_exit_code": killed_code,
        "outage_s": round(restarted_at - killed_at, 1),
        "planner_objects_before": planner_objects_before,
        "planner_objects_during_outage": planner_objects_during,
        "others_alive_during_outage": others_alive,
        "segmentation_kept_publishing": segmentation_kept_running,
        "goal_during_outage": goal_result,
        "resumed": resumed,
        "seconds_to_first_meshes_after_restart": round(time.monotonic() - restarted_at, 1) if resumed else None,
        "segmented_frames_after_restart": watch.totals()["segmentation"] - frames_at_restart,
        "restarted_node_diagnostics": {k: restarted.get(k) for k in ("frames_received", "frames_processed")},
        "restarted_log_tail": "" if resumed else graph["reconstruction"].log()[-2000:],
        "last_segmented_frame_s_after_kill": round(segmented_at[-1] - killed_at, 1) if segmented_at else None,
        "fresh_reader": None if resumed else frames_to_a_fresh_reader(probe, 10.0),
        "alive_after": {k: p.alive() for k, p in graph.items()},
    }


def frames_to_a_fresh_reader(probe, duration_s: float) -> dict:
    """Segmented frames a newly created subscription receives in duration_s, and how many the
    segmentation node says it published meanwhile: tells a wedged publisher from a wedged reader."""
    published_before = probe.diagnostic_number("segmentation_node", "frames_published", 0)
    fresh = probe.record(SegmentedFrame, "arm/segmented_frame", 10, keep=1)
    probe.wait_until(lambda: False, duration_s)
    published = probe.diagnostic_number("segmentation_node", "frames_published", 0) - published_before
    with probe.lock:
        return {"received": fresh.total, "published": int(published), "seconds": duration_s}
