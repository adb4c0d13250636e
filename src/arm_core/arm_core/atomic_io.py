"""Atomic file writes: readers see the old file or the complete new one, never a partial file.

Each write goes to a temporary file in the destination's folder (same file system), which then
replaces the destination with os.replace; on any failure the temporary file is removed.
"""

import json
import os
import pathlib
import tempfile
from collections.abc import Callable


def atomic_write(path, write: Callable[[pathlib.Path], object]) -> pathlib.Path:
    """Call write(temp_path) to write the content, then move it to path (parent folders are
    created). The temporary name ends with path's suffix (np.savez adds no '.npz'). Returns path."""
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=f".tmp{path.suffix}")
    os.close(fd)
    try:
        write(pathlib.Path(tmp))
        os.replace(tmp, path)
    except BaseException:
        pathlib.Path(tmp).unlink(missing_ok=True)
        raise
    return path


def atomic_write_bytes(path, data: bytes) -> pathlib.Path:
    return atomic_write(path, lambda tmp: tmp.write_bytes(data))


def atomic_write_text(path, text: str) -> pathlib.Path:
    return atomic_write(path, lambda tmp: tmp.write_text(text))


def atomic_write_json(path, value, **dumps_kwargs) -> pathlib.Path:
    """json.dumps(value, **dumps_kwargs), serialized before anything is written."""
    return atomic_write_text(path, json.dumps(value, **dumps_kwargs))
