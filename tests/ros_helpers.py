"""Helpers for integration tests: real node processes over DDS on an isolated domain."""

import os
import pathlib
import signal
import subprocess
import time

import rclpy
from ament_index_python.packages import get_package_prefix

from arm_ros.processes import config_file


def executable(package: str, name: str) -> str:
    return str(pathlib.Path(get_package_prefix(package)) / "lib" / package / name)


def start_node(package: str, name: str, *ros_args: str, params_file: str | None = None, log=None):
    cmd = [executable(package, name), "--ros-args"]
    if params_file:
        cmd += ["--params-file", str(config_file(params_file))]
    cmd += list(ros_args)
    return subprocess.Popen(
        cmd, stdout=log or subprocess.PIPE, stderr=subprocess.STDOUT, env=os.environ.copy(), start_new_session=True
    )


def stop_node(process, timeout_s: float = 10.0) -> int:
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout_s)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    return process.returncode


def spin_until(node, predicate, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
        if predicate():
            return True
    return predicate()
