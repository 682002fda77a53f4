"""Operator-facing units: values typed at the console may carry a unit suffix.

Code and files are SI; the console accepts `5deg`, `0.1rad`, `10mm`, `0.25m` (a bare
number is SI: rad or m) and displays degrees and millimetres where people read them.
"""
from __future__ import annotations

import math
import re

_NUMBER = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([a-zA-Z]*)\s*$")
ANGLE_UNITS = {"": 1.0, "rad": 1.0, "deg": math.pi / 180.0, "mrad": 1e-3}
LENGTH_UNITS = {"": 1.0, "m": 1.0, "mm": 1e-3, "cm": 1e-2}


class UnitError(ValueError):
    pass


def _parse(text: str, units: dict[str, float], kind: str) -> float:
    match = _NUMBER.match(text)
    if not match:
        raise UnitError(f"{text!r} is not {'an' if kind == 'angle' else 'a'} {kind} (e.g. {'5deg' if kind == 'angle' else '10mm'})")
    value, unit = float(match.group(1)), match.group(2)
    if unit not in units:
        raise UnitError(f"{text!r}: unknown {kind} unit {unit!r} (use {', '.join(u for u in units if u)})")
    return value * units[unit]


def parse_angle(text: str) -> float:
    return _parse(text, ANGLE_UNITS, "angle")


def parse_length(text: str) -> float:
    return _parse(text, LENGTH_UNITS, "length")
