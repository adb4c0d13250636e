"""The one node-process helper: start ARM node executables as processes (own process group, output in
a log file, parameter files from arm_bringup's share folder), watch their memory and stop them.
Used by bringup, the demo, the robustness harness and the integration tests."""

from __future__ import annotations

import os
import pathlib
import signal
import subprocess
import time

from ament_index_python.packages import PackageNotFoundError, get_package_prefix, get_package_share_directory

NODES = {
    "sim": ("arm_sim", "sim_node", "sim_node.yaml"),
    "segmentation": ("arm_segmentation", "segmentation_node", "segmentation_node.yaml"),
    "reconstruction": ("arm_reconstruction", "reconstruction_node", "reconstruction_node.yaml"),
    "planner": ("arm_planner", "plan_node", "plan_node.yaml"),
    "record": ("arm_bags", "record", None),
    "replay": ("arm_bags", "replay", None),
}


def executable(key: str) -> pathlib.Path:
    """The installed executable of a node key of NODES (install/<pkg>/lib/<pkg>/<exe>)."""
    package, name, _ = NODES[key]
    try:
        prefix = pathlib.Path(get_package_prefix(package))
    except PackageNotFoundError:
        prefix = pathlib.Path("/nonexistent")
    return prefix / "lib" / package / name


def node_built(key: str) -> bool:
    return executable(key).exists()


def config_file(name: str) -> pathlib.Path | None:
    """A parameter file installed by arm_bringup (share/arm_bringup/config/<name>); None if absent."""
    try:
        path = pathlib.Path(get_package_share_directory("arm_bringup")) / "config" / name
    except PackageNotFoundError:
        return None
    return path if path.exists() else None


def rss_mb(pid: int) -> float:
    """Resident set size of a process, MiB (nan once it is gone)."""
    try:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float("nan")


def cpu_s(pid: int) -> float:
    """CPU seconds a process has used, user and system, all its threads (nan once it is gone)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            fields = stat.read().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return float("nan")
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime: fields 14, 15


def _param_text(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_param_text(v) for v in value) + "]"
    return str(value)


class NodeProcess:
    """One node executable in its own process group, output in a log file."""

    def __init__(
        self,
        key: str,
        log_path,
        params: dict | None = None,
        remaps: dict | None = None,
        args: tuple = (),
        params_file: bool = True,
        env: dict | None = None,
        ros_args: tuple = (),
    ):
        """args: before --ros-args; ros_args: raw arguments after it (-p, -r); env: variables set for
        this process on top of the current environment."""
        self.key = key
        self.log_path = pathlib.Path(log_path)
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        cmd = [str(executable(key)), *args, "--ros-args"]
        config = config_file(NODES[key][2]) if params_file and NODES[key][2] else None
        if config:
            cmd += ["--params-file", str(config)]
        for name, value in (params or {}).items():
            cmd += ["-p", f"{name}:={_param_text(value)}"]
        for source, target in (remaps or {}).items():
            cmd += ["-r", f"{source}:={target}"]
        cmd += list(ros_args)
        self.cmd = cmd
        self._log = open(self.log_path, "w")  # noqa: SIM115 - lives as long as the process
        self.started_s = time.monotonic()
        self.process = subprocess.Popen(
            cmd, stdout=self._log, stderr=subprocess.STDOUT, env={**os.environ, **(env or {})}, start_new_session=True
        )

    @property
    def pid(self) -> int:
        return self.process.pid

    def alive(self) -> bool:
        return self.process.poll() is None

    def rss_mb(self) -> float:
        return rss_mb(self.pid) if self.alive() else float("nan")

    def cpu_s(self) -> float:
        return cpu_s(self.pid) if self.alive() else float("nan")

    def kill9(self) -> None:
        if self.alive():
            self.process.send_signal(signal.SIGKILL)
        self.process.wait()

    def stop(self, sig=signal.SIGINT, timeout_s: float = 15.0) -> int:
        """Send sig and wait; SIGKILL after timeout_s. Returns the exit code."""
        if self.alive():
            self.process.send_signal(sig)
            try:
                self.process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self._log.close()
        return self.process.returncode

    def dump_stacks_and_stop(self, settle_s: float = 2.0) -> int:
        """For a process that hangs: SIGABRT, which makes a process started with PYTHONFAULTHANDLER=1
        write every thread's Python stack to its log, then stop it. Returns the exit code."""
        if self.alive():
            self.process.send_signal(signal.SIGABRT)
            self.wait(settle_s)
        return self.stop()

    def wait(self, timeout_s: float) -> int | None:
        try:
            return self.process.wait(timeout_s)
        except subprocess.TimeoutExpired:
            return None

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")
