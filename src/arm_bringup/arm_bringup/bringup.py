"""Bring up the ARM node graph as separate processes (ros2 launch is not installable here; on a full
ROS 2 install use `ros2 launch arm_bringup arm_pipeline.launch.py` instead).

Usage: bringup [--nodes sim segmentation reconstruction planner] [--log-dir DIR] [--camera PRESET]

When the sim runs, the other nodes run on its simulated time (use_sim_time:=true, /clock).
--camera realsense_d4xx | azure_kinect | oak_d | path/to/preset.yaml: a real camera's driver topics
instead of the simulator (arm_bringup/camera_presets.py); the driver itself is started separately.
"""

import argparse
import pathlib
import sys
import time

from arm_bringup.camera_presets import PresetError, load_preset, node_options
from arm_reconstruction.checkpoint import default_checkpoint_path
from arm_ros.processes import NodeProcess, node_built

GRAPH_NODES = ("sim", "segmentation", "reconstruction", "planner")


def node_available(key: str) -> bool:
    """The node is built (and, for reconstruction, its shipped checkpoint is there)."""
    return node_built(key) and (key != "reconstruction" or default_checkpoint_path("arm").exists())


class Graph:
    """The node processes of one bring-up; stops them all on exit, SIGINT first. With use_sim_time,
    every node but the sim (the clock source) runs on /clock."""

    def __init__(self, log_dir: pathlib.Path, use_sim_time: bool = False):
        self.log_dir = pathlib.Path(log_dir)
        self.use_sim_time = use_sim_time
        self.processes: dict[str, NodeProcess] = {}
        self.log_dir.mkdir(parents=True, exist_ok=True)

    def start(self, key: str, *ros_args: str, params: dict | None = None, remaps: dict | None = None) -> NodeProcess:
        """Start a node with its installed parameter file; ros_args follow --ros-args (-p, -r), after
        params and remaps (a camera preset's, see camera_presets.node_options)."""
        params = ({"use_sim_time": True} if self.use_sim_time and key != "sim" else {}) | (params or {})
        process = NodeProcess(key, self.log_dir / f"{key}.log", params=params, remaps=remaps, ros_args=ros_args)
        self.processes[key] = process
        return process

    def alive(self) -> dict[str, bool]:
        return {k: p.alive() for k, p in self.processes.items()}

    def stop(self, timeout_s: float = 10.0) -> dict[str, int]:
        return {k: p.stop(timeout_s=timeout_s) for k, p in self.processes.items()}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--nodes", nargs="*", default=list(GRAPH_NODES), choices=list(GRAPH_NODES))
    parser.add_argument("--log-dir", default="log/bringup")
    parser.add_argument("--camera", help="camera preset (config/cameras/<name>.yaml or a path): no simulator")
    args = parser.parse_args()
    try:
        preset = load_preset(args.camera) if args.camera else None
    except PresetError as error:
        parser.error(str(error))
    nodes = [k for k in args.nodes if preset is None or k != "sim"]
    with Graph(pathlib.Path(args.log_dir), use_sim_time="sim" in nodes) as graph:
        for key in nodes:
            if node_available(key):
                graph.start(key, **node_options(preset, key))
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
