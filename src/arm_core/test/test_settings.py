"""Settings carry their description and range; nodes, YAML and flags derive from one dataclass."""

import argparse
from dataclasses import dataclass, field

import pytest

from arm_core.settings import (
    add_arguments,
    changed,
    from_arguments,
    parameters_of,
    setting,
    settings_of,
    with_values,
)


@dataclass
class Inner:
    steps: int = setting(200, "Steps", 1, 5000, parameter=True)
    temperature: float = setting(0.05, "Temperature", 1e-4, 10.0)
    untracked: int = 3  # a plain field is no setting


@dataclass
class Outer:
    inner: Inner = field(default_factory=Inner)
    mode: str = setting("stream", "Mode", choices=("plan_only", "stream"), parameter=True)
    base_xyz_m: list = setting([-0.55, 0.0, 0.0], "Base position, m")
    on: bool = setting(True, "Switch")


def test_settings_are_found_in_nested_dataclasses_and_parameters_are_the_marked_ones():
    config = Outer()
    assert [s.name for s in settings_of(config)] == ["steps", "temperature", "mode", "base_xyz_m", "on"]
    assert [s.name for s in parameters_of(config)] == ["steps", "mode"]
    steps = settings_of(config)[0]
    assert steps.path == ("inner", "steps") and steps.flag == "--steps" and (steps.low, steps.high) == (1, 5000)


def test_values_are_checked_and_set_without_touching_the_original():
    config = Outer()
    new = with_values(config, {"steps": 5, "temperature": 1, "mode": "plan_only", "base_xyz_m": (0, 1, 2)})
    assert new.inner.steps == 5 and new.inner.temperature == 1.0 and isinstance(new.inner.temperature, float)
    assert new.mode == "plan_only" and new.base_xyz_m == [0, 1, 2]
    assert config.inner.steps == 200 and config.mode == "stream", "the original is unchanged"
    assert changed(new, config) == {"steps": 5, "temperature": 1.0, "mode": "plan_only", "base_xyz_m": [0, 1, 2]}
    for values, words in (
        ({"steps": 0}, "outside"),
        ({"mode": "sometimes"}, "not one of"),
        ({"on": 1}, "must be bool"),
        ({"steps": True}, "must be int"),
        ({"base_xyz_m": [1.0]}, "needs 3 values"),
        ({"nothing": 1}, "has no settings"),
    ):
        with pytest.raises(ValueError, match=words):
            with_values(config, values)


def test_a_name_used_twice_is_refused():
    @dataclass
    class Twice:
        inner: Inner = field(default_factory=Inner)
        steps: int = setting(1, "Steps again")

    with pytest.raises(ValueError, match="used twice"):
        settings_of(Twice())


def test_command_line_flags_derive_from_the_settings():
    parser = argparse.ArgumentParser()
    names = add_arguments(parser, Outer(), ["steps", "on", "base_xyz_m", "mode"])
    args = parser.parse_args(["--steps", "7", "--no-on", "--base-xyz-m", "1", "2", "3"])
    config = from_arguments(Outer(), args, names)
    assert (config.inner.steps, config.on, config.base_xyz_m, config.mode) == (7, False, [1.0, 2.0, 3.0], "stream")
    with pytest.raises(SystemExit):
        parser.parse_args(["--mode", "sometimes"])
