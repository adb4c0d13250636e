"""Settings: dataclass fields that carry their own description and valid range.

A core's config dataclass is the one source of its settings. A node declares the fields marked
`parameter=True` as ROS parameters (arm_ros.common.declare_settings), the YAML files in config/ are
rendered from the same fields (arm_bringup.config_files), and a benchmark adds a command-line flag per
field (add_arguments / from_arguments). A nested dataclass field contributes its own settings; every
setting's name (its field name) is unique within the top-level config.
"""

from __future__ import annotations

import argparse
import copy
from dataclasses import dataclass, field, fields, is_dataclass, replace


def setting(default, description: str, low=None, high=None, choices=None, *, parameter: bool = False):
    """A dataclass field holding one setting. low/high: the valid closed range of a number; choices:
    the valid values of a string; parameter: a node declares it as a ROS parameter (the settings a
    robot user sets; the rest keep their defaults there and are set by benchmarks and tests)."""
    metadata = {
        "description": description,
        "low": low,
        "high": high,
        "choices": tuple(choices) if choices else None,
        "parameter": parameter,
    }
    if isinstance(default, (list, dict)):
        return field(default_factory=lambda: copy.deepcopy(default), metadata=metadata)
    return field(default=default, metadata=metadata)


@dataclass(frozen=True)
class Setting:
    path: tuple[str, ...]  # field names from the top-level config down to this one
    value: object  # the value in the config it was read from
    description: str
    low: object = None
    high: object = None
    choices: tuple | None = None
    parameter: bool = False

    @property
    def name(self) -> str:
        return self.path[-1]

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")

    def check(self, value):
        """value converted to the setting's type, or ValueError naming the setting and what is valid."""
        expected = type(self.value)
        if expected is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if expected is list:
            value = list(value)
            if self.value and len(value) != len(self.value):
                raise ValueError(f"{self.name} needs {len(self.value)} values, got {value}")
        elif not isinstance(value, expected) or isinstance(value, bool) != isinstance(self.value, bool):
            raise ValueError(f"{self.name} must be {expected.__name__}, got {value!r}")
        if self.choices and value not in self.choices:
            raise ValueError(f"{self.name}={value!r} is not one of {list(self.choices)}")
        if self.low is not None and not (self.low <= value <= self.high):
            raise ValueError(f"{self.name}={value} is outside [{self.low}, {self.high}]")
        return value


def settings_of(config) -> list[Setting]:
    """Every setting of a config dataclass instance (nested dataclasses included), with its value there."""
    found = _walk(config, ())
    names = [s.name for s in found]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise ValueError(f"{type(config).__name__}: setting names used twice: {repeated}")
    return found


def _walk(config, path: tuple[str, ...]) -> list[Setting]:
    found = []
    for f in fields(config):
        value = getattr(config, f.name)
        if is_dataclass(value):
            found += _walk(value, path + (f.name,))
        elif "description" in f.metadata:
            meta = f.metadata
            found.append(
                Setting(
                    path + (f.name,),
                    value,
                    meta["description"],
                    meta["low"],
                    meta["high"],
                    meta["choices"],
                    meta["parameter"],
                )
            )
    return found


def parameters_of(config) -> list[Setting]:
    """The settings a node declares as ROS parameters."""
    return [s for s in settings_of(config) if s.parameter]


def with_values(config, values: dict):
    """A copy of config with the named settings set (each checked); an unknown name is a ValueError."""
    by_name = {s.name: s for s in settings_of(config)}
    unknown = sorted(set(values) - set(by_name))
    if unknown:
        raise ValueError(f"{type(config).__name__} has no settings {unknown}")
    for name, value in values.items():
        config = _replace_at(config, by_name[name].path, by_name[name].check(value))
    return config


def _replace_at(config, path: tuple[str, ...], value):
    if len(path) == 1:
        return replace(config, **{path[0]: value})
    return replace(config, **{path[0]: _replace_at(getattr(config, path[0]), path[1:], value)})


def changed(config, reference) -> dict:
    """name -> value of the settings in which config differs from reference (same class)."""
    before = {s.name: s.value for s in settings_of(reference)}
    return {s.name: s.value for s in settings_of(config) if s.value != before[s.name]}


def add_arguments(parser: argparse.ArgumentParser, config, names=None) -> list[str]:
    """One flag per setting of config (or of those named), its default the value in config; returns
    the names of the settings given flags, for from_arguments."""
    added = []
    for s in settings_of(config):
        if names is not None and s.name not in names:
            continue
        help_text = s.description + (f" [{s.low}, {s.high}]" if s.low is not None else "")
        if isinstance(s.value, bool):
            parser.add_argument(s.flag, action=argparse.BooleanOptionalAction, default=s.value, help=help_text)
        elif isinstance(s.value, list):
            kind = type(s.value[0]) if s.value else float
            parser.add_argument(s.flag, type=kind, nargs="+", default=s.value, help=help_text)
        else:
            parser.add_argument(s.flag, type=type(s.value), default=s.value, choices=s.choices, help=help_text)
        added.append(s.name)
    return added


def from_arguments(config, args: argparse.Namespace, names: list[str]):
    """config with the named settings (add_arguments' return) set from parsed args."""
    return with_values(config, {name: getattr(args, name) for name in names})


@dataclass
class GoalPauseSettings:
    """How a perception node yields the CPU while the planner serves a goal (arm_ros.goal_activity)."""

    pause_during_goals: bool = setting(
        True,
        "Hold camera frames back while the planner serves a goal (false for closed-loop re-planning)",
        parameter=True,
    )
    manipulate_action: str = setting("arm/manipulate", "The planner's action, for pause_during_goals", parameter=True)
    goal_pause_limit_s: float = setting(60.0, "Longest pause for one goal, s", 1.0, 3600.0, parameter=True)


# Perception nodes run at Linux niceness 10: on a loaded machine planning and control, at 0, get the
# CPU first and perception runs on what is left.
PERCEPTION_NICENESS = 10


def cpu_niceness_setting():
    return setting(PERCEPTION_NICENESS, "Process CPU niceness (0: normal priority, 19: lowest)", 0, 19, parameter=True)
