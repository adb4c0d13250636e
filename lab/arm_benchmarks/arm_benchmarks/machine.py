"""The machine a benchmark ran on, as every summary.json and report names it: the CPU model (figures
differ between CPUs, and outcomes of chaotic rollouts with their rounding), the cores and Python."""

from __future__ import annotations

import os
import pathlib
import platform


def cpu_model(cpuinfo: str | None = None) -> str:
    """The CPU's model name from /proc/cpuinfo (or the given text), else platform's processor or
    architecture."""
    if cpuinfo is None:
        try:
            cpuinfo = pathlib.Path("/proc/cpuinfo").read_text()
        except OSError:
            cpuinfo = ""
    for line in cpuinfo.splitlines():
        key, _, value = line.partition(":")
        if key.strip() in ("model name", "Model") and value.strip():
            return " ".join(value.split())
    return platform.processor() or platform.machine()


def machine_description() -> str:
    """e.g. 'x86_64, AMD EPYC, 2 cores, python 3.11.7'."""
    return f"{platform.machine()}, {cpu_model()}, {os.cpu_count()} cores, python {platform.python_version()}"
