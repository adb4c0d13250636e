"""Error-log analysis of node logs: rate-limited error lines and Python tracebacks."""

from __future__ import annotations

import dataclasses
import re

ERROR_LINE = re.compile(
    r"^\[ERROR\] \[(?P<time>[\d.]+)\] \[(?P<node>[^\]]+)\]: (?P<text>.*?)"
    r"(?: \[(?P<cause>[^\[\]]+), seen (?P<seen>\d+)x\])?$",
    re.M,
)


@dataclasses.dataclass
class ErrorLine:
    time_s: float
    node: str
    text: str
    cause: str
    seen: int


def error_lines(log_text: str) -> list[ErrorLine]:
    return [
        ErrorLine(float(m["time"]), m["node"], m["text"], m["cause"] or m["text"], int(m["seen"] or 1))
        for m in ERROR_LINE.finditer(log_text)
    ]


def rate_limit_violations(lines: list[ErrorLine], period_s: float = 5.0) -> list[str]:
    """Causes logged twice within period_s (a burst of one cause must give one line per period)."""
    last: dict[str, float] = {}
    violations = []
    for line in lines:
        if line.cause in last and line.time_s - last[line.cause] < 0.9 * period_s:
            violations.append(f"{line.cause!r} logged again after {line.time_s - last[line.cause]:.2f} s")
        last[line.cause] = line.time_s
    return violations


def tracebacks(log_text: str) -> list[str]:
    """The last line of every Python traceback in a log."""
    found = []
    lines = log_text.splitlines()
    for i, line in enumerate(lines):
        if line.startswith("Traceback (most recent call last)"):
            tail = next((t for t in lines[i + 1 :] if t and not t.startswith((" ", "\t"))), "?")
            found.append(tail)
    return found
