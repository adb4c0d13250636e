"""The run key of a cached benchmark result: a digest of what the result depends on.

run_key(settings, checkpoints, packages) digests the settings (JSON, sorted keys), the bytes of the
checkpoint files, and every .py file under each named package's directory (sorted by path, each with
its path relative to the package), so that a changed setting, checkpoint or line of code in any
package the result depends on gives a new key and the cache is not reused.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import pathlib
from collections.abc import Iterable

KEY_LENGTH = 12


def package_dir(name: str) -> pathlib.Path:
    """Directory of an importable package, found without importing it."""
    spec = importlib.util.find_spec(name)
    if spec is None or not spec.submodule_search_locations:
        raise ValueError(f"'{name}' is not an importable package")
    return pathlib.Path(next(iter(spec.submodule_search_locations))).resolve()


def package_sources(name: str) -> list[pathlib.Path]:
    """Every .py file under the package's directory, sorted."""
    root = package_dir(name)
    return sorted(p for p in root.rglob("*.py") if p.is_file() and "__pycache__" not in p.parts)


def run_key(settings: dict, checkpoints: Iterable = (), packages: Iterable[str] = ()) -> str:
    """Digest (12 hex digits) of the settings, the checkpoint files' bytes and the packages' sources."""
    digest = hashlib.sha256(json.dumps(settings, sort_keys=True, default=str).encode())
    for path in checkpoints:
        path = pathlib.Path(path)
        digest.update(b"checkpoint\0" + path.name.encode() + b"\0")
        digest.update(path.read_bytes() if path.is_file() else b"<missing>")
    for name in packages:
        root = package_dir(name)
        digest.update(b"package\0" + name.encode() + b"\0")
        for path in package_sources(name):
            digest.update(path.relative_to(root).as_posix().encode() + b"\0")
            digest.update(path.read_bytes())
    return digest.hexdigest()[:KEY_LENGTH]
