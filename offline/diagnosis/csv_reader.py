"""Any CSV recording into the diagnosis table: with or without a header, columns by name or
number, scaled and offset (`column_spec`), put on a uniform time base (`time_base`), and a
report of how every column was read (what `diagnose --dry-run` prints)."""
from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from spacearm.offline.diagnosis.column_spec import ColumnSpec, alias
from spacearm.offline.diagnosis.recording_io import RecordingFormatError, RecordingTable
from spacearm.offline.diagnosis.time_base import sync_time_base, uniform
from spacearm.controller.recording.csv_export import SYNC_COUNTER_MAX, WRENCH_COLUMNS, dq_cmd_columns

MAX_BAD_FRACTION = 0.2       # a column with more unreadable cells than this is refused, not patched
# No angle, length, speed, torque or force of an arm reaches this in SI units; a cell that does
# is corrupt (a lost delimiter joining two numbers), and left in it would swamp every fit.
IMPLAUSIBLE = 1e9
MAX_BYTES = 2_000_000_000
COMMAND_MODES = ("recorded", "measured")


@dataclass
class ReadReport:
    source: str
    header: bool
    columns: list[str] = field(default_factory=list)     # one line per column of ours
    notes: list[str] = field(default_factory=list)

    def lines(self) -> list[str]:
        kind = "with a header row" if self.header else "without a header (columns by number)"
        return [f"{self.source}: CSV {kind}"] + ["  " + c for c in self.columns] + self.notes


def _is_number(cell: str) -> bool:
    try:
        float(cell)
        return True
    except ValueError:
        return False


def _rows(path: Path) -> list[list[str]]:
    if path.stat().st_size > MAX_BYTES:
        raise RecordingFormatError(f"{path}: larger than {MAX_BYTES / 1e9:.0f} GB")
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise RecordingFormatError(f"{path}: not a UTF-8 text file (byte {exc.start})") from None
    if "\x00" in text:
        raise RecordingFormatError(f"{path}: binary data (NUL bytes), not a CSV")
    lines = [line for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise RecordingFormatError(f"{path}: empty file")
    first = lines[0]
    delimiter = max((",", ";", "\t"), key=first.count)
    try:
        if first.count(delimiter) == 0 and len(first.split()) > 1:
            return [line.split() for line in lines]          # whitespace-separated columns
        return [[c.strip() for c in row] for row in csv.reader(io.StringIO("\n".join(lines)), delimiter=delimiter)]
    except csv.Error as exc:
        raise RecordingFormatError(f"{path}: not a CSV ({exc})") from None


def _cell(row: list[str], col: int) -> float:
    try:
        return float(row[col])
    except (ValueError, IndexError):
        return float("nan")


def _resolve(spec: ColumnSpec, header: list[str] | None, width: int, path: Path) -> int:
    if isinstance(spec.source, int):
        if spec.source >= width:
            raise RecordingFormatError(f"{path}: --columns {spec.text!r}: the file has {width} columns")
        return spec.source
    if header is None:
        raise RecordingFormatError(f"{path}: no header row, so --columns {spec.text!r} must name columns by "
                                   "number (#1, #2, ...)")
    if spec.source not in header:
        raise RecordingFormatError(f"{path}: --columns {spec.text!r}: no column {spec.source!r} in the header")
    return header.index(spec.source)


def _velocity_offset_columns(values: dict[str, np.ndarray], n: int, command: str, report: ReadReport) -> list[str]:
    """The names of the commanded velocity offset's columns dq_cmd_1..n, completed with zeros,
    when the recording has any (our CSV since the daemon records it); [] otherwise. With
    --command measured they are dropped: the measured motion's steps carry its velocity already."""
    names = dq_cmd_columns(n)
    columns = {k: values.pop(k) for k in [k for k in values if k.startswith("dq_cmd_")]}
    if not any(k in columns for k in names):
        return []
    if command == "measured":
        report.notes.append("commanded velocity offset (dq_cmd) not used: the command is the measured position")
        return []
    missing = [k for k in names if k not in columns]
    for k in names:
        values[k] = columns[k] if k in columns else np.zeros(len(values["q_1"]))
    report.notes.append("commanded velocity offset: recorded (dq_cmd), replayed as sent"
                        + (f"; {', '.join(missing)} not in the recording, taken as 0" if missing else ""))
    return names


def read_any_csv(path: str | Path, specs: list[ColumnSpec] | None = None, command: str = "recorded",
                 period: float | None = None) -> tuple[RecordingTable, ReadReport]:
    """The recording as a table plus the report of how it was read. Raises
    RecordingFormatError with one line naming the file and the problem."""
    path = Path(path)
    if command not in COMMAND_MODES:
        raise RecordingFormatError(f"--command {command!r}: expected one of {', '.join(COMMAND_MODES)}")
    rows = _rows(path)
    header = None if all(_is_number(c) for c in rows[0] if c) else rows[0]
    body = rows[1:] if header is not None else rows
    width = max(len(header) if header else 0, max((len(r) for r in body), default=0))
    report = ReadReport(str(path), header is not None)
    mapping: dict[str, ColumnSpec] = {}
    for i, name in enumerate(header or []):
        ours = alias(name)
        if ours is not None and ours not in mapping:
            mapping[ours] = ColumnSpec(ours, i, text=name)
    for spec in specs or []:
        mapping[spec.ours] = spec
    index = {ours: _resolve(s, header, width, path) for ours, s in mapping.items()}
    joint_numbers = [int(k.rsplit("_", 1)[1]) for k in mapping if k.rsplit("_", 1)[0] in ("q_cmd", "q", "dq", "tau")]
    n = max(joint_numbers, default=0)
    if n == 0:
        raise RecordingFormatError(f"{path}: no joint columns found; name them q_1..n (and q_cmd_i, dq_i, tau_i) "
                                   "or map them with --columns, e.g. q_1..6=#2..7")
    if n > 64:
        raise RecordingFormatError(f"{path}: {n} joints: more than 64 is not an arm recording")
    missing_q = [i for i in range(1, n + 1) if f"q_{i}" not in mapping]
    if missing_q:
        raise RecordingFormatError(f"{path}: no measured position for joint(s) {missing_q} (map with --columns q_i=...)")
    missing_cmd = [i for i in range(1, n + 1) if f"q_cmd_{i}" not in mapping]
    if missing_cmd and command != "measured":
        raise RecordingFormatError(f"{path}: no commanded position q_cmd_{missing_cmd[0]}: map it with --columns or, "
                                   "if the recording has none, use --command measured")
    if len(body) < 10:
        raise RecordingFormatError(f"{path}: {len(body)} data rows; need at least 10")

    ragged = sum(1 for r in body if len(r) < width)
    values: dict[str, np.ndarray] = {}
    for ours, col in index.items():
        spec = mapping[ours]
        raw = np.full(len(body), np.nan)
        for k, r in enumerate(body):
            if col < len(r) and r[col] != "":
                try:
                    raw[k] = float(r[col])
                except ValueError:
                    pass
        with np.errstate(all="ignore"):
            x = raw * spec.scale + spec.offset
        x[~np.isfinite(x)] = np.nan
        huge = np.abs(x) > IMPLAUSIBLE if ours != "t" else np.zeros(len(x), bool)  # t may count from an epoch
        x[huge] = np.nan
        bad = int(np.isnan(x).sum())
        if bad > MAX_BAD_FRACTION * len(x):
            raise RecordingFormatError(f"{path}: column for {ours} ({spec.describe(header).split('<- ')[1]}): "
                                       f"{bad} of {len(x)} cells empty or not numbers")
        values[ours] = x
        note = f"{bad} unreadable cells" + (f", {int(huge.sum())} of them beyond +-{IMPLAUSIBLE:.0e}" if huge.any() else "")
        report.columns.append(spec.describe(header) + (f"  ({note})" if bad else ""))
    if ragged:
        report.notes.append(f"{ragged} rows have fewer than {width} fields (missing cells bridged)")

    if "t" in values:
        t = values.pop("t")
        if header is not None and "sync" in header:
            sync = np.array([_cell(r, header.index("sync")) for r in body])
            by_sync = sync_time_base(t, sync, SYNC_COUNTER_MAX)
            if by_sync is not None and np.any(np.abs(by_sync - t) > 1e-9):
                report.notes.append(f"time base: the SYNC counter (one row per SYNC, {by_sync[1] - by_sync[0]:.4g} s "
                                    f"apart); the t column's gaps ({float(np.max(np.diff(t))):.3g} s at most) are "
                                    "cycles the controller skipped, in which the simulated plant did not advance")
                t = by_sync
    elif period:
        t = period * np.arange(len(body))
        report.notes.append(f"no time column: rows taken {period:g} s apart (--rate)")
    else:
        raise RecordingFormatError(f"{path}: no time column t (map it with --columns t=#1 or give --rate HZ)")
    if command == "measured":
        for i in range(1, n + 1):
            values[f"q_cmd_{i}"] = values[f"q_{i}"]
        report.notes.append("commanded position: the measured position (--command measured), so the replay follows"
                            " the recorded motion and only torques and forces are compared")
    zero = np.zeros(len(t))
    offset = _velocity_offset_columns(values, n, command, report)
    absent = [name for name in [f"dq_{i}" for i in range(1, n + 1)] + [f"tau_{i}" for i in range(1, n + 1)]
              + list(WRENCH_COLUMNS) if name not in values]
    for name in absent:
        values[name] = zero
    if absent:
        report.notes.append(f"not in the recording (taken as 0, not compared): {', '.join(absent)}")
    try:
        grid, out, timing = uniform(t, values, period)
    except ValueError as exc:
        raise RecordingFormatError(f"{path}: time column: {exc}") from None
    report.notes += timing.lines()
    if len(grid) < 10:
        raise RecordingFormatError(f"{path}: {len(grid)} usable rows after cleaning the time base; need at least 10")
    joint = lambda p: np.column_stack([out[f"{p}_{i}"] for i in range(1, n + 1)])
    table = RecordingTable(grid, joint("q_cmd"), joint("q"), joint("dq"), joint("tau"),
                           np.column_stack([out[c] for c in WRENCH_COLUMNS]),
                           dq_cmd=np.column_stack([out[c] for c in offset]) if offset else None)
    for name, x in (("q", table.q), ("q_cmd", table.q_cmd)):
        if not np.all(np.isfinite(x)):
            raise RecordingFormatError(f"{path}: {name} has no finite values in some joint")
        if float(np.max(np.abs(x))) > 1e3 * math.pi:
            raise RecordingFormatError(f"{path}: {name} reaches {float(np.max(np.abs(x))):.3g}: not radians or "
                                       "metres (scale it with --columns, e.g. q_1=pos1*deg)")
    for name in ("dq", "tau", "wrench") + (("dq_cmd",) if offset else ()):
        arr = getattr(table, name)
        arr[~np.isfinite(arr)] = 0.0
    return table, report
