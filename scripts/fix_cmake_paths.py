"""Rewrite the ROS 2 wheels' build-host paths in the venv's CMake files to this machine's paths.

The wheels export CMake config that names /opt/python/cp311-cp311/... (the host that built them);
rosidl_generate_interfaces fails on those non-existent paths until they point at the local Python
include directory and numpy's include directory.
"""

import pathlib
import sys
import sysconfig

import numpy

BUILD_HOST_PYTHON_INCLUDE = "/opt/python/cp311-cp311/include/python3.11"
BUILD_HOST_NUMPY_INCLUDE = "/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include"


def fix_cmake_paths(venv: pathlib.Path) -> int:
    replacements = {
        BUILD_HOST_NUMPY_INCLUDE: numpy.get_include(),
        BUILD_HOST_PYTHON_INCLUDE: sysconfig.get_paths()["include"],
    }
    changed = 0
    for path in (venv / "share").rglob("*.cmake"):
        text = path.read_text(errors="surrogateescape")
        new = text
        for old, local in replacements.items():
            new = new.replace(old, local)
        if new != text:
            path.write_text(new, errors="surrogateescape")
            changed += 1
    return changed


if __name__ == "__main__":
    n = fix_cmake_paths(pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else ".venv").resolve())
    print(f"[fix_cmake_paths] rewrote {n} CMake files")
