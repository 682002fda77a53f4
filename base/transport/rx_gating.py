"""Untagged delivery on a redundant pair whose receivers sort frames by line themselves.

The simulated nodes on a pair each listen on one line (firmware_sim/line_selection.py): a
frame reaches a node's entry points only if rx_line() names that node's line, checked by a
gate around each entry point. Tagging every frame and passing every gate costs a call each
(issue 34: ~40 calls a lockstep cycle), yet while every node is on one line that has no fault,
every frame of that line reaches every node. So while that holds (`raw_line`), the pair hands
frames of that line to such receivers straight, neither wrapped nor tagged, and their gates
are off; a frame of the other line, or any frame while the nodes are split, is delivered
tagged under a hold that keeps the gates on (and the raw line tagged, for a frame delivered
within its handling) until it has been handled.

    pair.gate_receivers(gate)     # gate(on: bool) turns the receivers' gates on or off
    pair.set_common_line(line)    # the line every node is on, None while they are split

Which receivers: those that say `rx_line_gated = True` (they read rx_line() only through those
gates); every other listener of the pair gets every frame tagged as before. A receiver that
reads no line (the master's) is none of this, and a pair with observers, a note set or a
standby filter (the master's) never goes raw. A frame already on its way straight when a node
toggles away still reaches that node, as a frame on the wire as the node switched would.
"""
from __future__ import annotations

import threading
from collections.abc import Callable


class RxGating:
    """The pair's raw line and the holds on it (under `_lock`); the pair owns one."""

    def __init__(self, pair):
        self.pair = pair
        self.gate: Callable[[bool], None] | None = None
        self.raw_line: int | None = None     # read unlocked by deliveries: a hold re-decides under the lock
        self._gates_on: bool | None = None
        self._holds = 0
        self._lock = threading.Lock()
        self._handlers: list[tuple[object, object]] = []   # (line queue, _LineListener) of gated receivers

    def attach(self, gate: Callable[[bool], None]) -> None:
        self.gate = gate
        for fault in self.pair.faults:
            fault.watch(self.refresh)       # a fault on the raw line ends raw delivery at once
        with self._lock:
            self._apply(force=True)

    def detach(self) -> None:
        for fault in self.pair.faults:
            fault.unwatch(self.refresh)

    def add(self, line_queue, listener) -> None:
        """A gated receiver's listener on an in-process line: its handler follows the raw line."""
        with self._lock:
            self._handlers.append((line_queue, listener))
            self._apply(force=True)

    def refresh(self) -> None:
        with self._lock:
            self._apply()

    def hold(self) -> None:
        with self._lock:
            self._holds += 1
            if self._holds == 1:
                self._apply()

    def release(self) -> None:
        with self._lock:
            self._holds -= 1
            if self._holds == 0:
                self._apply()

    def held(self, deliver: Callable[[int, bytes, float], None]) -> Callable[[int, bytes, float], None]:
        """`deliver` (which tags the frame) under a hold."""
        hold, release = self.hold, self.release

        def deliver_held(can_id: int, data: bytes, timestamp: float) -> None:
            hold()
            try:
                deliver(can_id, data, timestamp)
            finally:
                release()
        return deliver_held

    def _apply(self, force: bool = False) -> None:
        """Under the lock: decide the raw line; gates on before any frame goes tagged, off only
        after the raw line's frames go straight."""
        pair, line = self.pair, self.pair.tx_common_line
        raw = line if (self.gate is not None and line is not None and self._holds == 0
                       and pair.faults[line].mode == "ok" and not pair.rx_observers
                       and pair.rx_note is None and pair.standby_passes is None) else None
        if raw == self.raw_line and not force:
            return
        if raw is None:
            self._set_gates(True)
        self.raw_line = raw
        for line_queue, listener in self._handlers:
            line_queue.set_handler(listener, listener.handler(raw))
        if raw is not None:
            self._set_gates(False)

    def _set_gates(self, on: bool) -> None:
        if self.gate is not None and on != self._gates_on:
            self.gate(on)
            self._gates_on = on
