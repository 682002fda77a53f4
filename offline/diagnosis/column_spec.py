"""How each column of someone else's recording becomes one of ours: `--columns` expressions.

    tau_3=#14*0.125          column 14 (1-based, header or not) times 0.125
    q_1=pos1*deg             column `pos1`, in degrees
    q_2=#3*deg+1.5708        scale first, then add an offset (SI, after scaling)
    tau_1..7=#16..22         a range: seven columns mapped at once
    dq_1..7=dq1..7           names with a number range: dq1 .. dq7

Units allowed as factors are the console's (deg, mrad, mm, cm, ...) plus a few of the
torque/current world (mNm, kNm); anything else is a plain number. Our names are
t, q_cmd_i, q_i, dq_i, tau_i, the wrench columns and, optionally, dq_cmd_i (the velocity
offset sent with the command, rad/s).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

from spacearm.offline.diagnosis.recording_io import RecordingFormatError
from spacearm.controller.recording.csv_export import WRENCH_COLUMNS


class ColumnSpecError(RecordingFormatError):
    """A bad --columns expression (a RecordingFormatError: the console prints it the same way)."""


UNIT_FACTORS = {"rad": 1.0, "deg": math.pi / 180.0, "mrad": 1e-3, "urad": 1e-6, "m": 1.0, "mm": 1e-3, "cm": 1e-2,
                "s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9, "Nm": 1.0, "mNm": 1e-3, "kNm": 1e3, "N": 1.0,
                "rpm": 2.0 * math.pi / 60.0, "degps": math.pi / 180.0}
JOINT_PREFIXES = ("q_cmd", "dq_cmd", "q", "dq", "tau")
_OURS = re.compile(r"^(t|(?:q_cmd|dq_cmd|q|dq|tau)_\d+|" + "|".join(WRENCH_COLUMNS) + r")$")
_RANGE_OURS = re.compile(r"^(q_cmd|dq_cmd|q|dq|tau)_(\d+)\.\.(\d+)$")
_RANGE_THEIRS = re.compile(r"^(#|.*?)(\d+)\.\.(\d+)$")


@dataclass(frozen=True)
class ColumnSpec:
    ours: str                 # our column name
    source: str | int         # their column: a header name, or a 0-based index
    scale: float = 1.0
    offset: float = 0.0
    text: str = ""            # the expression as given (for --dry-run)

    def describe(self, header: list[str] | None) -> str:
        where = f"column {self.source + 1}" if isinstance(self.source, int) else f"column {self.source!r}"
        if isinstance(self.source, int) and header:
            where += f" ({header[self.source]!r})" if self.source < len(header) else ""
        how = "" if self.scale == 1.0 else f" x {self.scale:.6g}"
        how += "" if self.offset == 0.0 else f" {'+' if self.offset > 0 else '-'} {abs(self.offset):.6g}"
        return f"{self.ours:<8} <- {where}{how}"


def _number(text: str, item: str) -> float:
    text = text.strip()
    if text in UNIT_FACTORS:
        return UNIT_FACTORS[text]
    try:
        value = float(text)
    except ValueError:
        raise ColumnSpecError(f"--columns {item!r}: {text!r} is neither a number nor a unit "
                              f"({', '.join(sorted(UNIT_FACTORS))})") from None
    if not math.isfinite(value):
        raise ColumnSpecError(f"--columns {item!r}: {text!r} is not a finite number")
    return value


def _source(text: str, item: str) -> str | int:
    text = text.strip()
    if text.startswith("#"):
        try:
            number = int(text[1:])
        except ValueError:
            raise ColumnSpecError(f"--columns {item!r}: {text!r}: expected #N, a column number from 1") from None
        if number < 1:
            raise ColumnSpecError(f"--columns {item!r}: column numbers start at 1")
        return number - 1
    if not text:
        raise ColumnSpecError(f"--columns {item!r}: no column named after '='")
    return text


def _expression(ours: str, expr: str, item: str) -> ColumnSpec:
    """SOURCE [(*|/) FACTOR]... [(+|-) OFFSET]"""
    m = re.match(r"^\s*(#\d+|[^*/]+?)\s*((?:[*/][^*/+]+?)*)\s*(?:([+-])\s*([\d.eE+-]+))?\s*$", expr)
    if not m:
        raise ColumnSpecError(f"--columns {item!r}: expected OURS=SOURCE[*SCALE][+OFFSET]")
    source = _source(m.group(1), item)
    scale = 1.0
    for op, factor in re.findall(r"([*/])\s*([^*/]+)", m.group(2) or ""):
        value = _number(factor, item)
        if op == "/":
            if value == 0.0:
                raise ColumnSpecError(f"--columns {item!r}: division by zero")
            value = 1.0 / value
        scale *= value
    offset = 0.0
    if m.group(3):
        offset = _number(m.group(4), item) * (-1.0 if m.group(3) == "-" else 1.0)
    return ColumnSpec(ours, source, scale, offset, item)


def parse_columns(text: str | None) -> list[ColumnSpec]:
    """The `--columns` option as a list of specs (ranges expanded)."""
    if not text:
        return []
    specs: list[ColumnSpec] = []
    for item in (s.strip() for s in text.split(",")):
        if not item:
            continue
        if "=" not in item:
            raise ColumnSpecError(f"--columns entry {item!r}: expected OURS=THEIRS (e.g. tau_3=#14*0.125)")
        ours, expr = (s.strip() for s in item.split("=", 1))
        ranged = _RANGE_OURS.match(ours)
        if ranged is None:
            if not _OURS.match(ours):
                raise ColumnSpecError(f"--columns {item!r}: {ours!r} is not one of ours (t, q_cmd_i, q_i, dq_i, "
                                      f"tau_i, {', '.join(WRENCH_COLUMNS)})")
            specs.append(_expression(ours, expr, item))
            continue
        prefix, a, b = ranged.group(1), int(ranged.group(2)), int(ranged.group(3))
        head, _, tail = expr.partition("*") if "*" in expr else expr.partition("/")
        op = "*" if "*" in expr else "/" if "/" in expr else ""
        theirs = _RANGE_THEIRS.match(head.strip())
        if theirs is None or b < a or a < 1:
            raise ColumnSpecError(f"--columns {item!r}: a range maps to a range of the same length "
                                  "(e.g. q_1..7=#2..8 or dq_1..7=dq1..7)")
        c, d = int(theirs.group(2)), int(theirs.group(3))
        if d - c != b - a:
            raise ColumnSpecError(f"--columns {item!r}: {b - a + 1} of ours but {d - c + 1} of theirs")
        for k in range(b - a + 1):
            one = f"{theirs.group(1)}{c + k}" + (op + tail if op else "")
            specs.append(_expression(f"{prefix}_{a + k}", one, item))
    seen = set()
    for s in specs:
        if s.ours in seen:
            raise ColumnSpecError(f"--columns: {s.ours!r} is mapped twice")
        seen.add(s.ours)
    return specs


_ALIAS = re.compile(r"^(q_cmd|qcmd|q_d|q|dq|qd|tau|torque)_?(\d+)$", re.IGNORECASE)
_ALIAS_PREFIX = {"q_cmd": "q_cmd", "qcmd": "q_cmd", "q_d": "q_cmd", "q": "q", "dq": "dq", "qd": "dq", "tau": "tau",
                 "torque": "tau"}


def alias(name: str) -> str | None:
    """Our name for a common header spelling (q1, dq_1, tau7, torque3, q_cmd1), or None."""
    name = name.strip()
    if _OURS.match(name):
        return name
    m = _ALIAS.match(name)
    if m and int(m.group(2)) >= 1:
        return f"{_ALIAS_PREFIX[m.group(1).lower()]}_{int(m.group(2))}"
    if name.lower() in ("t", "time", "time_s", "timestamp", "stamp"):
        return "t"
    return None
