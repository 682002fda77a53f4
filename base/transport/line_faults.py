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
"""
from __future__ import annotations

import random
import threading

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

    def clear(self) -> None:
        self.set("ok")

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
