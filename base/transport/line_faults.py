"""Faults of one physical CAN line, as far as a frame transport can express them.

A line is one bus spec (`virtual:arm-a`, `loopback:arm-a@H:P`, `socketcan:vcan0`). Every
redundant-pair endpoint in this process attached to a line shares that line's LineFault
(`line_fault(spec)`), so cutting `virtual:arm-a` cuts it for the master and every simulated
node at once, as a cut cable would. The loopback hub applies the same faults to a channel
for all its clients (hub.py `fault`).

    cut              no frame passes, in either direction
    babble           a babbling node floods the line with highest-priority frames
                     (ID BABBLE_ID): every other frame loses arbitration and is lost,
                     receivers see the flood instead (BABBLE_BURST frames per lost frame)
    stuck_dominant   the line is held dominant: no frame can be sent; receivers see error
                     frames (python-can is_error_frame) instead, one per attempted frame
    error_passive    a node in error-passive retransmits: each frame is lost with
                     probability `loss` (the transport has no bit errors, only lost frames)
    intermittent     a loose connector: frames lost with probability `loss` (default 0.5)
    ok               no fault

Random losses come from a generator seeded per line (`seed`), so a test repeats exactly.

A fault file injects them at run time from another process (`spacearm hub --fault-file`,
`spacearm sim --fault-file`; `spacearm bus fault FILE LINE MODE` edits one): one
`LINE MODE [LOSS]` per text line, `#` comments; a line not named has no fault. The file is
re-read when it changes (FaultFileWatcher, or the hub's own loop).
"""
from __future__ import annotations

import os
import random
import threading
from collections.abc import Callable
from pathlib import Path

MODES = ("ok", "cut", "babble", "stuck_dominant", "error_passive", "intermittent")

BABBLE_ID = 0x001        # the highest-priority ID after NMT (0x000): it wins every arbitration
BABBLE_DATA = b"\xff" * 8
BABBLE_BURST = 4         # flood frames a receiver sees per frame the flood kept off the line


class LineFaultError(ValueError):
    """An unknown fault mode or a loss probability outside 0..1."""


class LineFault:
    """The fault state of one line (thread-safe: set from a test or command, read by senders)."""

    def __init__(self, spec: str = "", seed: int = 0):
        self.spec = spec
        self.mode = "ok"
        self.loss = 0.0
        self._rng = random.Random(seed)
        self._lock = threading.Lock()
        self.frames_lost = 0      # frames this fault kept off the line
        self.flood_frames = 0     # babble frames delivered instead
        self._watchers: list[Callable[[], None]] = []

    def set(self, mode: str, loss: float | None = None, seed: int | None = None) -> None:
        if mode not in MODES:
            raise LineFaultError(f"unknown line fault '{mode}' (known: {', '.join(MODES)})")
        if loss is None:
            loss = {"intermittent": 0.5, "error_passive": 0.2}.get(mode, 0.0)
        if not 0.0 <= loss <= 1.0:
            raise LineFaultError(f"loss probability {loss} is not within 0..1")
        with self._lock:
            self.mode, self.loss = mode, float(loss)
            if seed is not None:
                self._rng.seed(seed)
            watchers = list(self._watchers)
        for watcher in watchers:        # outside the lock: a watcher may take locks of its own
            watcher()

    def clear(self) -> None:
        self.set("ok")

    def watch(self, callback: Callable[[], None]) -> None:
        """`callback()` after every set(), in the setting thread (a pair that delivers frames of
        a sound line without checking the fault per frame: redundant.py)."""
        with self._lock:
            self._watchers.append(callback)

    def unwatch(self, callback: Callable[[], None]) -> None:
        with self._lock:
            if callback in self._watchers:
                self._watchers.remove(callback)

    @property
    def active(self) -> bool:
        return self.mode != "ok"

    def passes(self) -> bool:
        """Does the next frame sent on this line reach the other nodes?"""
        mode = self.mode
        if mode == "ok":
            return True
        if mode in ("intermittent", "error_passive"):
            with self._lock:
                lost = self._rng.random() < self.loss
        else:
            lost = True
        if lost:
            self.frames_lost += 1
        return not lost

    def replacement(self) -> list[tuple[int, bytes, bool]]:
        """What receivers see instead of a frame this fault kept off the line:
        (can_id, data, is_error_frame) tuples."""
        if self.mode == "babble":
            self.flood_frames += BABBLE_BURST
            return [(BABBLE_ID, BABBLE_DATA, False)] * BABBLE_BURST
        if self.mode == "stuck_dominant":
            return [(0, b"", True)]
        return []

    def describe(self) -> str:
        if self.mode in ("intermittent", "error_passive"):
            return f"{self.mode} (loss {self.loss:g})"
        return self.mode


_LINES: dict[str, LineFault] = {}
_LINES_LOCK = threading.Lock()


def line_fault(spec: str) -> LineFault:
    """The fault state shared by every endpoint of line `spec` in this process."""
    key = spec.strip()
    with _LINES_LOCK:
        fault = _LINES.get(key)
        if fault is None:
            fault = _LINES[key] = LineFault(key, seed=sum(key.encode()))
        return fault


def clear_all() -> None:
    """Every line of this process back to no fault (tests)."""
    with _LINES_LOCK:
        faults = list(_LINES.values())
    for fault in faults:
        fault.clear()


def parse_fault_text(text: str) -> tuple[dict[str, tuple[str, float | None]], list[str]]:
    """A fault file's text -> ({line name: (mode, loss)}, ["N: problem", ...] for lines ignored)."""
    wanted: dict[str, tuple[str, float | None]] = {}
    problems: list[str] = []
    for number, text_line in enumerate(text.splitlines(), 1):
        words = text_line.split("#")[0].split()
        if not words:
            continue
        try:
            if len(words) not in (2, 3):
                raise LineFaultError("expected LINE MODE [LOSS]")
            entry = (words[1], float(words[2]) if len(words) == 3 else None)
            LineFault().set(*entry)        # checks mode and loss
            wanted[words[0]] = entry
        except (LineFaultError, ValueError) as exc:
            problems.append(f"{number}: {exc}")
    return wanted, problems


def write_fault_entry(path: Path, line: str, mode: str, loss: float | None = None) -> None:
    """Set one line's entry in a fault file (`ok` removes it), keeping the others; the file is
    replaced in one rename, so a reader never sees half of it. Raises LineFaultError."""
    LineFault().set(mode, loss)
    if not line or any(c.isspace() or c == "#" for c in line):
        raise LineFaultError(f"line name {line!r}: one word, no '#'")
    path = Path(path)
    kept = []
    if path.exists():
        for text_line in path.read_text().splitlines():
            words = text_line.split("#")[0].split()
            if not words or words[0] != line:
                kept.append(text_line)
    if mode != "ok":
        kept.append(f"{line} {mode}" + (f" {loss:g}" if loss is not None else ""))
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text("".join(f"{t}\n" for t in kept))
    tmp.replace(path)


class FaultFileWatcher:
    """Applies a fault file to named lines while it runs (`lines`: every name a line may go by,
    e.g. A, arm-a and virtual:arm-a, -> its LineFault); `report(text)` gets one line per change
    or ignored text line."""

    PERIOD = 0.05   # s between looks at the file's modification time

    def __init__(self, path: Path, lines: dict[str, LineFault], report: Callable[[str], None]):
        self.path, self.lines, self.report = Path(path), lines, report
        self._stamp: int | None = -1
        self._stop = threading.Event()
        self.poll()
        self._thread = threading.Thread(target=self._run, name="line-fault-file", daemon=True)
        self._thread.start()

    def poll(self) -> None:
        try:
            stamp = self.path.stat().st_mtime_ns
            text = self.path.read_text()
        except OSError:
            stamp, text = None, ""
        if stamp == self._stamp:
            return
        self._stamp = stamp
        wanted, problems = parse_fault_text(text)
        for problem in problems:
            self.report(f"{self.path}:{problem} (ignored)")
        for name in wanted:
            if name not in self.lines:
                self.report(f"{self.path}: no line {name!r} here (known: {', '.join(self.lines)}; ignored)")
        target: dict[int, tuple[LineFault, str, float | None, str]] = {}
        for name, fault in self.lines.items():
            target.setdefault(id(fault), (fault, "ok", None, name))
        for name, (mode, loss) in wanted.items():
            fault = self.lines.get(name)
            if fault is not None:
                target[id(fault)] = (fault, mode, loss, name)
        for fault, mode, loss, name in target.values():
            wanted_state = LineFault()
            wanted_state.set(mode, loss)
            if (fault.mode, fault.loss) != (wanted_state.mode, wanted_state.loss):
                fault.set(mode, loss)
                self.report(f"line {name} ({fault.spec}): {fault.describe()}")

    def _run(self) -> None:
        while not self._stop.wait(self.PERIOD):
            self.poll()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(1.0)
