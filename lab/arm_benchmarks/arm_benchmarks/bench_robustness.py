"""bench_robustness: the heavier robustness run, over DDS with real node processes.

Phases (each saved to <out>/phases/<phase>.json; --resume skips the saved ones):
  bad_input_*   malformed and extreme inputs per node (segmentation, reconstruction with a 40-object
                frame, planner, sim), bags (corrupt/truncated/missing through the core and `replay`)
  parameters    invalid parameters at start-up (exit code 2, clear message, no traceback)
  qos           a 30 Hz 640x480 camera into segmentation with a best-effort vs a reliable subscription
  load_fault    the camera at 30 Hz for --duration-s into the full graph (latest-frame processing,
                memory growth), then kill -9 of the reconstruction node and its restart

Writes <out>/summary.json, <out>/report.md and PNG plots (memory, lag, rates).
    bench_robustness [--duration-s 60] [--out results/robustness] [--resume] [--only PHASE ...]
"""

import argparse
import json
import pathlib
import shutil
import sys
import tempfile
import time

import matplotlib
import numpy as np
from sensor_msgs.msg import Image
from tqdm import tqdm

from arm_bags.bags import BagError, BagReader
from arm_benchmarks.machine import machine_description
from arm_benchmarks.robustness.bags import broken_bags, write_camera_bag
from arm_benchmarks.robustness.cases.parameters import run_parameter_validation
from arm_benchmarks.robustness.cases.planner import run_planner_bad_inputs
from arm_benchmarks.robustness.cases.reconstruction import run_reconstruction_bad_inputs
from arm_benchmarks.robustness.cases.segmentation import run_segmentation_bad_inputs
from arm_benchmarks.robustness.cases.sim import run_sim_bad_inputs
from arm_benchmarks.robustness.frames import render_frames
from arm_benchmarks.robustness.load import rate_against_first_window, run_fault, run_load, start_graph, stop_graph
from arm_benchmarks.robustness.logs import tracebacks
from arm_benchmarks.robustness.messages import camera_messages
from arm_benchmarks.robustness.nodes import ROOT, reconstruction_checkpoint, reconstruction_params
from arm_benchmarks.robustness.parameters import convention_report
from arm_benchmarks.robustness.probe import Probe
from arm_ros.common import sensor_qos, use_large_socket_buffers, use_private_domain
from arm_ros.processes import NodeProcess, node_built
from arm_segmentation.node_config import SegmentationNodeConfig

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)

PHASES = (
    "bad_input_segmentation",
    "bad_input_reconstruction",
    "bad_input_planner",
    "bad_input_sim",
    "bags",
    "parameters",
    "qos",
    "load_fault",
)
# the trajectories go out on the topic, where the harness inspects them
FAST_PLANNER = {"steps": 5, "settle_s": 0.0, "nthread": 1, "controller_interface": "topic"}


def _frames(width: int, height: int) -> dict:
    return {
        "normal": render_frames(6, width, height, seed=1)[0],
        "empty": render_frames(0, width, height, seed=1)[0],
        "crowded": render_frames(40, width, height, seed=2, settle_s=0.8)[0],
    }


def _with_node(key: str, log_dir: pathlib.Path, runner, **node_kwargs) -> dict:
    process = NodeProcess(key, log_dir / f"{key}.log", **node_kwargs)
    probe = Probe()
    try:
        report = runner(probe, process)
        report["conventions"] = convention_report(probe, key)
    finally:
        probe.close()
        exit_code = process.stop()
    report["exit_code_on_sigint"] = exit_code
    return report


def phase_bad_input_segmentation(args, work: pathlib.Path) -> dict:
    frames = _frames(args.width, args.height)
    return _with_node(
        "segmentation",
        work,
        lambda probe, process: run_segmentation_bad_inputs(probe, process, frames),
        params={"image_reliability": "reliable"},
    )


def phase_bad_input_reconstruction(args, work: pathlib.Path) -> dict:
    params = reconstruction_params()
    if params is None:
        return {"skipped": "no reconstruction checkpoint"}
    frames = _frames(args.width, args.height)
    return _with_node(
        "reconstruction",
        work,
        lambda probe, process: run_reconstruction_bad_inputs(probe, process, frames, crowded=True),
        params=params,
    )


def phase_bad_input_planner(args, work: pathlib.Path) -> dict:
    return _with_node("planner", work, run_planner_bad_inputs, params={**FAST_PLANNER, "execution": "stream"})


def phase_bad_input_sim(args, work: pathlib.Path) -> dict:
    params = {"n_objects": 3, "camera_rate_hz": 0.2, "width": 160, "height": 120}
    return _with_node("sim", work, run_sim_bad_inputs, params=params)


def phase_bags(args, work: pathlib.Path) -> dict:
    """Broken bags through the core reader and through `replay` (which must exit 2, no traceback)."""
    frame = render_frames(2, 64, 48, seed=0)[0]
    good = [("/" + t, (i + 1) * 10**8, m) for i, (t, m) in enumerate(camera_messages(frame, 1.0).items())]
    cases = broken_bags(work, good)
    results = []
    for name, path in cases.items():
        try:
            with BagReader(path) as reader:
                list(reader.messages())
            core = "read without error"
        except BagError as error:
            core = f"BagError: {error}"[:200]
        process = NodeProcess("replay", work / f"replay_{len(results)}.log", args=(str(path),))
        code = process.wait(60.0)
        if code is None:
            process.stop()
        log = process.log()
        ok = core.startswith("BagError") and code == 2 and not tracebacks(log)
        results.append({"name": name, "core": core, "replay_exit_code": code, "ok": ok})
    return {"inputs_tried": len(results), "cases": results, "cases_failed": [r["name"] for r in results if not r["ok"]]}


def phase_parameters(args, work: pathlib.Path) -> dict:
    results = run_parameter_validation(work)
    return {
        "inputs_tried": len(results),
        "cases": results,
        "cases_failed": [f"{r['node']} {r['parameter']}={r['value']!r}" for r in results if not r["ok"]],
    }


def _delivery(work: pathlib.Path, bag: pathlib.Path, reliability: str, seconds: float) -> dict:
    """Over `seconds` of a looping 30 Hz camera bag: the fraction of rgb + depth images a plain
    subscriber with this reliability receives (transport only), and the segmented frames per second
    segmentation_node publishes with this image_reliability (transport + processing)."""
    seg = NodeProcess(
        "segmentation", work / f"segmentation_{reliability}.log", params={"image_reliability": reliability}
    )
    replay = NodeProcess(
        "replay",
        work / f"replay_{reliability}.log",
        args=(str(bag),),
        params={"loop": True, "wait_subscribers_s": 60.0},
    )
    probe = Probe()
    counters = [
        ("frames_sent", "bag_replayer", "frames_published"),
        ("segmented", "segmentation_node", "frames_published"),
    ]
    try:
        probe.watch_diagnostics()
        images = [
            probe.record(Image, t, sensor_qos(reliability, 10), keep=1)
            for t in ("camera/color/image_raw", "camera/depth/image_raw")
        ]
        probe.wait_until(lambda: probe.diagnostic_number("segmentation_node", "messages_received", 0) > 0, 60.0)
        start = {k: probe.diagnostic_number(node, key, 0) for k, node, key in counters}
        received_start = sum(i.total for i in images)
        began = time.monotonic()
        time.sleep(seconds)
        end = {k: probe.diagnostic_number(node, key, 0) for k, node, key in counters}
        received = sum(i.total for i in images) - received_start
        elapsed = time.monotonic() - began
    finally:
        probe.close()
        replay.stop()
        seg.stop()
    sent = 2 * (end["frames_sent"] - start["frames_sent"])
    return {
        "images_sent": int(sent),
        "images_received_by_plain_subscriber": int(received),
        "delivered_fraction": round(received / sent, 3) if sent else None,
        "segmented_frames_hz": round((end["segmented"] - start["segmented"]) / elapsed, 2),
    }


def phase_qos(args, work: pathlib.Path) -> dict:
    """Large images at 30 Hz with a best-effort vs a reliable subscription."""
    bag = work / "camera_bag"
    write_camera_bag(bag, render_frames(6, 640, 480, seed=3, count=3), args.camera_hz, joint_states=False)
    out = {reliability: _delivery(work, bag, reliability, args.qos_s) for reliability in ("best_effort", "reliable")}
    return {"camera_hz": args.camera_hz, "seconds": args.qos_s, "image_size": "640x480", **out}


def phase_load_fault(args, work: pathlib.Path) -> dict:
    params = reconstruction_params()
    if params is None:
        return {"skipped": "no reconstruction checkpoint"}
    bag = work / "camera_bag"
    write_camera_bag(bag, render_frames(6, args.width, args.height, seed=3, count=3), args.camera_hz)
    graph = start_graph(
        work, bag, params, args.image_reliability, planner_params={**FAST_PLANNER, "execution": "plan_only"}
    )
    probe = Probe()
    bar = tqdm(total=int(args.duration_s), desc="load", unit="s", leave=False)
    try:
        load = run_load(probe, graph, args.duration_s, progress=lambda s: bar.update(1))
        bar.close()
        fault = run_fault(probe, graph, load.pop("watch"), params, work / "reconstruction_restarted.log")
    finally:
        probe.close()
        stopped = stop_graph(graph)
    return {
        "camera_hz_requested": args.camera_hz,
        "image_size": f"{args.width}x{args.height}",
        "load": load,
        "fault": fault,
        "shutdown": stopped,
    }


def _keep_logs(work: pathlib.Path, target: pathlib.Path, lines: int = 300) -> None:
    """The last `lines` lines of every node log of a phase (the work directory is removed)."""
    for log in sorted(work.rglob("*.log")):
        destination = target / log.relative_to(work)
        destination.parent.mkdir(parents=True, exist_ok=True)
        destination.write_text("\n".join(log.read_text(errors="replace").splitlines()[-lines:]) + "\n")


def _plot(summary: dict, out: pathlib.Path) -> list[str]:

    written = []
    load = summary["phases"].get("load_fault", {}).get("load")
    if load and load.get("samples"):
        samples = load["samples"]
        t = [s["t_s"] for s in samples]
        fig, axes = plt.subplots(1, 2, figsize=(11, 4))
        for key in ("replay", "segmentation", "reconstruction", "planner"):
            series = [s.get(f"rss_mb_{key}", np.nan) for s in samples]
            axes[0].plot(t, np.asarray(series) - series[0], label=key)
        axes[0].axhline(50, color="k", ls="--", lw=0.8, label="50 MB limit")
        axes[0].set(xlabel="time since warm-up (s)", ylabel="RSS growth (MB)", title="memory under load")
        axes[0].legend(fontsize=8)
        for key, label in (("camera", "camera"), ("segmentation", "segmented frames"), ("reconstruction", "meshes")):
            counts = np.array([s[f"count_{key}"] for s in samples], float)
            axes[1].plot(t[1:], np.diff(counts) / np.maximum(np.diff(t), 1e-6), label=label)
        axes[1].set(xlabel="time since warm-up (s)", ylabel="messages / s", title="rates under load", yscale="log")
        axes[1].legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out / "load.png", dpi=110)
        plt.close(fig)
        written.append("load.png")
    rows = [
        (name.replace("bad_input_", ""), phase)
        for name, phase in summary["phases"].items()
        if isinstance(phase, dict) and "inputs_tried" in phase
    ]
    if rows:
        fig, ax = plt.subplots(figsize=(7, 3.5))
        names = [n for n, _ in rows]
        tried = [p["inputs_tried"] for _, p in rows]
        failed = [len(p.get("cases_failed", [])) for _, p in rows]
        ax.bar(names, tried, label="inputs tried")
        ax.bar(names, failed, label="handled wrongly", color="tab:red")
        ax.set(ylabel="cases", title="bad inputs per node")
        ax.legend()
        plt.setp(ax.get_xticklabels(), rotation=20, ha="right")
        fig.tight_layout()
        fig.savefig(out / "bad_inputs.png", dpi=110)
        plt.close(fig)
        written.append("bad_inputs.png")
    return written


def _figures(phases: dict) -> dict:
    """The headline numbers of the run."""
    figures = {}
    bad = {k: v for k, v in phases.items() if isinstance(v, dict) and "inputs_tried" in v}
    figures["inputs_tried"] = sum(v["inputs_tried"] for v in bad.values())
    figures["inputs_handled_wrongly"] = {k: v.get("cases_failed", []) for k, v in bad.items() if v.get("cases_failed")}
    figures["nodes_alive_after_bad_input"] = {k: v.get("alive") for k, v in bad.items() if "alive" in v}
    figures["tracebacks"] = {k: v.get("tracebacks") for k, v in bad.items() if v.get("tracebacks")}
    figures["distinct_reasons_not_logged"] = {
        k: v.get("reasons_not_logged") for k, v in bad.items() if v.get("reasons_not_logged")
    }
    conventions = {k: v.get("conventions") for k, v in bad.items() if v.get("conventions")}
    figures["convention_gaps"] = {
        k: {kk: vv for kk, vv in c.items() if isinstance(vv, list) and vv} for k, c in conventions.items()
    }
    figures["convention_gaps"] = {k: v for k, v in figures["convention_gaps"].items() if v}
    lf = phases.get("load_fault", {})
    if "load" in lf:
        load = lf["load"]
        figures["load"] = {
            "duration_s": load["duration_s"],
            "camera_hz_achieved": load["rates_hz"]["camera"],
            "segmented_frames_hz": load["rates_hz"]["segmentation"],
            "meshes_hz": load["rates_hz"]["reconstruction"],
            "rates_by_minute_hz": load.get("rates_by_minute_hz", {}),
            "cpu_s_per_s_by_minute": load.get("cpu_by_minute", {}),
            "segmentation_messages_taken_by_minute_hz": load.get("segmentation_messages_taken_by_minute_hz"),
            "segmentation_frame_ms_by_minute": load.get("segmentation_frame_ms_by_minute"),
            "rate_against_first_minute": {
                k: rate_against_first_window(v) for k, v in load.get("rates_by_minute_hz", {}).items()
            },
            "memory_growth_trend_mb": {k: v.get("trend_growth_mb") for k, v in load["memory"].items()},
            "memory_growth_floor_mb": {k: v.get("floor_growth_mb") for k, v in load["memory"].items()},
            "max_memory_growth_mb": {k: v["max_growth_mb"] for k, v in load["memory"].items()},
            "memory_growth_during_warmup_mb": {
                k: (round(v["start_mb"] - v["at_first_meshes_mb"], 1) if v["start_mb"] is not None else None)
                for k, v in load["memory"].items()
            },
            "lag_s": {
                k: {kk: v[kk] for kk in ("median_s", "max_s", "first_third_median_s", "last_third_median_s")}
                for k, v in load["lag"].items()
            },
            "all_alive": all(load["alive"].values()),
        }
        fault = lf["fault"]
        figures["fault"] = {
            "survived": fault["resumed"] and all(fault["alive_after"].values()),
            "planner_objects_kept_during_outage": fault["planner_objects_during_outage"],
            "goal_planned_during_outage": fault["goal_during_outage"].get("planned"),
            "seconds_to_first_meshes_after_restart": fault["seconds_to_first_meshes_after_restart"],
        }
        figures["shutdown_exit_codes"] = {k: v["exit_code"] for k, v in lf["shutdown"].items()}
        figures["shutdown_tracebacks"] = {k: v["tracebacks"] for k, v in lf["shutdown"].items() if v["tracebacks"]}
    if "qos" in phases and "reliable" in phases["qos"]:
        figures["qos"] = {
            k: {kk: phases["qos"][k].get(kk) for kk in ("delivered_fraction", "segmented_frames_hz")}
            for k in ("best_effort", "reliable")
        }
    return figures


def _report(summary: dict, plots: list[str]) -> str:
    lines = ["# Robustness benchmark", "", f"Command: `{summary['command']}`  ", f"Machine: {summary['machine']}", ""]
    lines += ["## Figures", "", "```json", json.dumps(summary["figures"], indent=2), "```", ""]
    for name, phase in summary["phases"].items():
        lines += [f"## {name}", ""]
        if "skipped" in phase:
            lines += [f"skipped: {phase['skipped']}", ""]
            continue
        if "cases" in phase:
            lines += ["| input | expected | outcome | ok |", "|---|---|---|---|"]
            for c in phase["cases"]:
                label = c.get("name") or f"{c.get('node')} {c.get('parameter')}={c.get('value')!r}"
                outcome = c.get("outcome", c.get("core", c.get("exit_code", "")))
                lines.append(
                    f"| {label} | {c.get('expect', c.get('kind', ''))} | {str(outcome)[:80]} | "
                    f"{'yes' if c['ok'] else '**no**'} |"
                )
            lines.append("")
    lines += [f"![{p}]({p})" for p in plots]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default=str(ROOT / "results" / "robustness"))
    parser.add_argument("--duration-s", type=float, default=60.0, help="load phase length after warm-up")
    parser.add_argument("--camera-hz", type=float, default=30.0)
    parser.add_argument("--qos-s", type=float, default=10.0, help="length of each QoS run")
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    parser.add_argument("--only", nargs="*", choices=PHASES, default=list(PHASES))
    parser.add_argument(
        "--image-reliability",
        choices=("best_effort", "reliable"),
        default=SegmentationNodeConfig().image_reliability,
        help="load_fault: segmentation_node's image subscriptions (default: the node's)",
    )
    parser.add_argument("--resume", action="store_true", help="keep phases already saved under <out>/phases")
    args = parser.parse_args(argv)
    use_private_domain()
    use_large_socket_buffers()  # the probes' process transports as the nodes' do
    missing = [k for k in ("sim", "segmentation", "reconstruction", "planner", "replay") if not node_built(k)]
    if missing:
        print(f"[bench_robustness] not built: {missing} (colcon build)")
        return 2
    out = pathlib.Path(args.out)
    (out / "phases").mkdir(parents=True, exist_ok=True)
    work_root = pathlib.Path(tempfile.mkdtemp(prefix="arm_robustness_"))
    phases = {}
    for name in tqdm(args.only, desc="bench_robustness", unit="phase"):
        saved = out / "phases" / f"{name}.json"
        if args.resume and saved.exists():
            phases[name] = json.loads(saved.read_text())
            continue
        work = work_root / name
        work.mkdir(parents=True)
        started = time.monotonic()
        result = globals()[f"phase_{name}"](args, work)
        result["wall_s"] = round(time.monotonic() - started, 1)
        result["run"] = {"finished": time.strftime("%Y-%m-%d %H:%M:%S"), "args": vars(args)}
        _keep_logs(work, out / "logs" / name)
        saved.write_text(json.dumps(result, indent=1, default=str))
        phases[name] = result
    for name in PHASES:  # phases of earlier runs that this one did not repeat
        saved = out / "phases" / f"{name}.json"
        if name not in phases and saved.exists():
            phases[name] = json.loads(saved.read_text())
    summary = {
        "command": "bench_robustness " + " ".join(argv if argv is not None else sys.argv[1:]),
        "machine": machine_description(),
        "reconstruction_checkpoint": str(reconstruction_checkpoint()),
        "figures": _figures(phases),
        "phases": phases,
    }
    plots = _plot(summary, out)
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=str))
    (out / "report.md").write_text(_report(summary, plots))
    shutil.rmtree(work_root, ignore_errors=True)
    print(json.dumps(summary["figures"], indent=1, default=str))
    print(f"[bench_robustness] wrote {out / 'summary.json'}, {out / 'report.md'} and {plots}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
