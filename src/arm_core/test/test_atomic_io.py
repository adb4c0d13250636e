import json

import numpy as np
import pytest

from arm_core.atomic_io import atomic_write, atomic_write_bytes, atomic_write_json, atomic_write_text


def test_writes_create_folders_and_replace_files(tmp_path):
    path = tmp_path / "a" / "b" / "value.json"
    atomic_write_json(path, {"x": 1}, indent=1)
    atomic_write_json(path, {"x": 2})
    assert json.loads(path.read_text()) == {"x": 2}
    assert atomic_write_text(tmp_path / "t.txt", "hello").read_text() == "hello"
    assert atomic_write_bytes(tmp_path / "b.bin", b"\x00\x01").read_bytes() == b"\x00\x01"
    arrays = atomic_write(tmp_path / "arrays.npz", lambda tmp: np.savez_compressed(tmp, a=np.arange(3)))
    with np.load(arrays) as data:
        assert np.array_equal(data["a"], np.arange(3))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "arrays.npz", "b.bin", "t.txt"]


def test_failed_write_leaves_the_old_file_and_no_partial_file(tmp_path):
    path = tmp_path / "state.bin"
    atomic_write_bytes(path, b"old")

    def half_write(tmp):
        tmp.write_bytes(b"partial")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        atomic_write(path, half_write)
    with pytest.raises(TypeError):
        atomic_write_json(path, {"not json": object()})
    assert path.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["state.bin"]
