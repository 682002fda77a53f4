"""The unit of a campaign figure, for the tables people read.

Trial kinds store their figures in SI under descriptive names; the console's tables and the
campaign's report.md show them in the units an operator thinks in: millimetres, degrees, newtons, seconds. The
unit follows from the name (the kinds name every figure after what it measures); a name no
rule knows is shown in SI and says so, never as a bare number.
"""
from __future__ import annotations

import math

# (what the name ends with or contains, display unit, factor from SI), first match wins
_RULES = (
    (("_success", "plausible", "visible", "named_first", "false_alarm", "within_15pct"), "0/1", 1.0),
    (("reduction",), "%", 100.0),
    (("error_to_floor", "noise_scale", "O3"), "ratio", 1.0),
    (("effects",), "count", 1.0),
    (("force",), "N", 1.0),
    (("torque",), "N m", 1.0),
    (("_time", "time"), "s", 1.0),
    (("angle", "rotation"), "deg", 180.0 / math.pi),
    (("lateral", "position", "tracking_error", "error", "floor", "noise"), "mm", 1e3),
)


def figure_unit(name: str) -> tuple[str, float]:
    """(display unit, factor from the stored SI value) of the figure `name`."""
    for keys, unit, factor in _RULES:
        if any(name.endswith(k) or k in name for k in keys):
            return unit, factor
    return "SI", 1.0
