import pytest

from arm_benchmarks.run_key import package_sources, run_key


@pytest.fixture
def package(tmp_path, monkeypatch):
    """An importable package 'runkey_probe' with a module and a subpackage, on sys.path."""
    root = tmp_path / "runkey_probe"
    (root / "sub").mkdir(parents=True)
    (root / "__init__.py").write_text("")
    (root / "core.py").write_text("SCALE = 1.0\n")
    (root / "sub" / "__init__.py").write_text("")
    (root / "sub" / "deep.py").write_text("def f():\n    return 1\n")
    (root / "notes.txt").write_text("not source")
    monkeypatch.syspath_prepend(str(tmp_path))
    return root


def test_same_inputs_give_the_same_key(package, tmp_path):
    checkpoint = tmp_path / "arm.pt"
    checkpoint.write_bytes(b"weights")
    key = run_key({"seed": 0, "steps": 200}, [checkpoint], ["runkey_probe"])
    assert key == run_key({"steps": 200, "seed": 0}, [checkpoint], ["runkey_probe"])
    assert len(key) == 12 and int(key, 16) >= 0


def test_sources_are_every_py_file_sorted(package):
    names = [p.relative_to(package).as_posix() for p in package_sources("runkey_probe")]
    assert names == ["__init__.py", "core.py", "sub/__init__.py", "sub/deep.py"]


def test_a_changed_source_file_of_a_dependency_changes_the_key(package):
    key = run_key({"seed": 0}, packages=["runkey_probe"])
    (package / "sub" / "deep.py").write_text("def f():\n    return 2\n")
    changed = run_key({"seed": 0}, packages=["runkey_probe"])
    assert changed != key
    (package / "sub" / "new.py").write_text("")
    assert run_key({"seed": 0}, packages=["runkey_probe"]) != changed
    (package / "notes.txt").write_text("edited")
    assert run_key({"seed": 0}, packages=["runkey_probe"]) == run_key({"seed": 0}, packages=["runkey_probe"])


def test_settings_and_checkpoint_bytes_change_the_key(package, tmp_path):
    checkpoint = tmp_path / "arm.pt"
    checkpoint.write_bytes(b"weights")
    key = run_key({"seed": 0}, [checkpoint], ["runkey_probe"])
    assert run_key({"seed": 1}, [checkpoint], ["runkey_probe"]) != key
    checkpoint.write_bytes(b"retrained")
    assert run_key({"seed": 0}, [checkpoint], ["runkey_probe"]) != key
    assert run_key({"seed": 0}, [checkpoint]) != run_key({"seed": 0}, [checkpoint], ["runkey_probe"])


def test_an_unknown_package_is_an_error():
    with pytest.raises(ValueError, match="not an importable package"):
        run_key({}, packages=["no_such_package_here"])
