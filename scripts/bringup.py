"""Bring up the ARM node graph as separate processes (ros2 launch is not installable here; on a full
ROS 2 install use the launch file in launch/arm_pipeline.launch.py instead).

Usage: python scripts/bringup.py [--nodes sim segmentation reconstruction planner] [--log-dir DIR]
"""

import argparse
import os
import pathlib
import signal
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
NODES = {
    "sim": ("arm_sim", "sim_node", "sim_node.yaml"),
    "segmentation": ("arm_segmentation", "segmentation_node", "segmentation_node.yaml"),
    "reconstruction": ("arm_reconstruction", "reconstruction_node", "reconstruction_node.yaml"),
    "planner": ("arm_planner", "plan_node", "plan_node.yaml"),
}


SHIPPED_CHECKPOINT = ROOT / "src" / "arm_reconstruction" / "arm_reconstruction" / "checkpoints" / "arm.pt"


def node_available(key: str) -> bool:
    """The node is built (and, for reconstruction, its shipped checkpoint is there)."""
    package, executable, _ = NODES[key]
    built = (ROOT / "install" / package / "lib" / package / executable).exists() and (
        ROOT / "src" / package / package / f"{executable}.py"
    ).exists()
    return built and (key != "reconstruction" or SHIPPED_CHECKPOINT.exists())


class Graph:
    """The node processes of one bring-up; stops them all on exit, SIGINT first."""

    def __init__(self, log_dir: pathlib.Path):
        self.log_dir = log_dir
        self.processes: dict[str, subprocess.Popen] = {}
        log_dir.mkdir(parents=True, exist_ok=True)

    def start(self, key: str, *extra_args: str) -> subprocess.Popen:
        package, executable, params = NODES[key]
        cmd = [str(ROOT / "install" / package / "lib" / package / executable), "--ros-args"]
        if (ROOT / "config" / params).exists():
            cmd += ["--params-file", str(ROOT / "config" / params)]
        cmd += list(extra_args)
        log = open(self.log_dir / f"{key}.log", "w")  # noqa: SIM115 - lives as long as the process
        process = subprocess.Popen(
            cmd, stdout=log, stderr=subprocess.STDOUT, env=os.environ.copy(), start_new_session=True
        )
        self.processes[key] = process
        return process

    def alive(self) -> dict[str, bool]:
        return {k: p.poll() is None for k, p in self.processes.items()}

    def stop(self, timeout_s: float = 10.0) -> dict[str, int]:
        for process in self.processes.values():
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        deadline = time.monotonic() + timeout_s
        codes = {}
        for key, process in self.processes.items():
            try:
                process.wait(max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
            codes[key] = process.returncode
        return codes

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--nodes", nargs="*", default=list(NODES), choices=list(NODES))
    parser.add_argument("--log-dir", default=str(ROOT / "log" / "bringup"))
    args = parser.parse_args()
    with Graph(pathlib.Path(args.log_dir)) as graph:
        for key in args.nodes:
            if node_available(key):
                graph.start(key)
                print(f"[bringup] started {key} (log: {args.log_dir}/{key}.log)")
            else:
                print(f"[bringup] {key} is not built yet; skipped")
        try:
            while all(graph.alive().values()):
                time.sleep(0.5)
        except KeyboardInterrupt:
            pass
        dead = [k for k, ok in graph.alive().items() if not ok]
        if dead:
            print(f"[bringup] node(s) exited: {dead}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
