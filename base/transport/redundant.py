"""A redundant pair of CAN lines as one python-can bus: `A+B`.

    virtual:arm-a+virtual:arm-b           two in-process buses
    loopback:arm-a+loopback:arm-b         two channels of the loopback hub
    socketcan:vcan0+socketcan:vcan1       two SocketCAN interfaces

Line 0 (A) is the nominal line, line 1 (B) the redundant one; both use one transport kind.
The pair models ECSS-E-ST-50-15C's two bus access architectures in one class:

* parallel access (the master): frames of both lines are received, each tagged with its
  line (`rx_line()` in the receiving thread, `rx_observers(line, can_id, data, t)`), and
  every frame is sent on the active line (`active`), which the master's redundancy manager
  moves (drivers/line_redundancy.py); `standby_passes(can_id)`, when set, names the frames of
  the line that is not active that still reach the application (the master: heartbeats and
  EMCY only; the standard's master watches the standby line for the nodes' life, it does not
  run process data off it), while the observers still see all of them;
  `tx_watch[can_id]` are callbacks(line, can_id) for the few COB-IDs someone counts (SYNC),
  looked up by COB-ID so the other frames cost nothing; `rx_note`, when set (two sets, one
  per line), takes the COB-IDs of the active line's frames other than heartbeats in place of
  the observers on the in-process pair (one set insertion per frame; the master folds them
  in at its next SYNC or timer pass);
* selective access (each simulated node): `tx_router(can_id) -> line` sends a frame on the
  line its sender listens on (None: on both, for frames of no node), and the simulator
  delivers a received frame only to the nodes listening on its line
  (firmware_sim/line_selection.py); `tx_owners[can_id].line`, where known, spares the router
  call per frame of a burst, and `tx_common_line`, when set, is the line every sender of
  `tx_owners` is on (a burst of known senders then goes there whole, no look-up per frame).

Faults of one line (line_faults.py: cut, babble, stuck_dominant, error_passive,
intermittent) are applied where a frame enters the line, so every receiver loses the same
frame, and again on receipt for the deterministic ones (a cut line also cuts frames of a
plain bus attached to it).

Cost: a second line must not make a cycle dearer (issue 34: <= 10 %). On the in-process pair a
frame costs one call (each listener's per-frame function, built at attach time for its line and
target), one fault check and the observers on top of one line; the thread-local is set only
for listeners that read it (`needs_rx_line`, default True; the master's listener says False);
a burst goes to its line in one call, with no per-frame routing (the master's: the active line;
the nodes': `tx_common_line` while they are all on one line); an unwatched frame of the master
on a sound line is sent without `_admit`. While every simulated node is on one sound line,
the simulator gets that line's frames with no per-frame function at all and its nodes'
line gates are off (rx_gating.py: `gate_receivers`, `set_common_line`).

Why a thread-local for the receive line: python-can's Listener API has no place for it,
and the pair delivers each frame in the thread that reads it (the sender's thread on the
in-process bus, the Notifier's otherwise), so the line of the frame being handled is the
one this thread set last.
"""
from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from operator import itemgetter

import can

from .line_faults import LineFault, line_fault
from .rx_gating import RxGating

PAIR_SEPARATOR = "+"
LINE_NAMES = ("A", "B")
_READ_POLL = 0.1   # s: a line reader's recv timeout, bounds shutdown
_can_id = itemgetter(0)


class _RxState(threading.local):
    line: int | None = None     # every thread starts with it: a hot path reads `.line`, no getattr call
    held: "RedundantBus | None" = None     # the pair whose frame this reader handed out under a hold
    # The pair whose recv() set `.line` in this thread: that tag outlives the call (the reader
    # asks rx_line() after it), so it ends when the pair does, or a later in-process run in
    # the same thread read a frame of a pair long gone as "on line B" (a lockstep test after
    # tests/transport: both bus lines lost).
    read_from: "RedundantBus | None" = None


_rx = _RxState()
rx_state = _rx     # the thread-local behind rx_line(): `.line`, for per-frame hot paths


def rx_line() -> int | None:
    """The line (0 = A, 1 = B) of the frame this thread is delivering, None off a pair."""
    return _rx.line


def split_pair(spec: str) -> tuple[str, str] | None:
    """'KIND:A+KIND:B' -> ('KIND:A', 'KIND:B'); None for a single line. Raises ValueError."""
    if PAIR_SEPARATOR not in spec:
        return None
    parts = [p.strip() for p in spec.split(PAIR_SEPARATOR)]
    if len(parts) != 2 or not all(parts):
        raise ValueError(f"bus '{spec}': a redundant pair is two lines, e.g. virtual:arm-a+virtual:arm-b")
    kinds = {p.partition(":")[0] for p in parts}
    if len(kinds) != 1:
        raise ValueError(f"bus '{spec}': both lines of a pair use one transport (got {', '.join(sorted(kinds))})")
    if parts[0] == parts[1]:
        raise ValueError(f"bus '{spec}': the two lines of a pair must differ")
    return parts[0], parts[1]


def line_channel(spec: str) -> str:
    """A line's name in a CAN trace's channel column, as `candump -l any` names an interface:
    'virtual:arm-a' -> arm-a, 'loopback:arm-a@127.0.0.1:5000' -> arm-a, 'socketcan:vcan1' -> vcan1."""
    return spec.partition(":")[2].partition("@")[0] or spec


class _LineListener(can.Listener):
    """Delivers one line's frames to an application listener in the sender's thread
    (the in-process bus), tagged with the line.

    `on_frame` is built here, once, for this line and this target (issue 34: a second line must
    cost a cycle almost nothing, and this runs for every frame): the line, its fault, the
    target's handler and whether the target reads the thread-local are fixed at attach time,
    so a frame pays no branch on them."""

    def __init__(self, pair: "RedundantBus", line: int, target: can.Listener):
        self.pair, self.line, self.target = pair, line, target
        # it reads rx_line() only through gates the pair turns off while this line is raw (rx_gating.py)
        self.gated = getattr(target, "rx_line_gated", False)
        on_frame = getattr(target, "on_frame", None)
        if on_frame is None:     # a listener of Messages only: one built per frame
            def on_frame(can_id: int, data: bytes, timestamp: float) -> None:
                target.on_message_received(can.Message(
                    timestamp=timestamp, arbitration_id=can_id, data=data, is_extended_id=False, check=False))
        self.raw = on_frame
        deliver = self._frame_handler(on_frame, getattr(target, "needs_rx_line", True))
        self.on_frame = pair.rx_gating.held(deliver) if self.gated else deliver

    def handler(self, raw_line: int | None) -> Callable[[int, bytes, float], None]:
        """A gated receiver's handler while `raw_line` is the pair's raw line."""
        return self.raw if self.line == raw_line else self.on_frame

    def _frame_handler(self, on_frame, tags: bool) -> Callable[[int, bytes, float], None]:
        pair, line = self.pair, self.line
        fault, blocked, rx = pair.faults[line], pair._rx_blocked, _rx

        def deliver(can_id: int, data: bytes, timestamp: float) -> None:
            if fault.mode != "ok" and blocked(line):
                return
            if line == pair.active:
                note = pair.rx_note
                if note is not None and can_id & 0x780 != 0x700:
                    note[line].add(can_id)      # instead of the observers: the owner folds it in later
                else:
                    for observer in pair.rx_observers:
                        observer(line, can_id, data, timestamp)
            else:
                for observer in pair.rx_observers:
                    observer(line, can_id, data, timestamp)
                passes = pair.standby_passes
                if passes is not None and not passes(can_id):
                    return
            if not tags:          # fixed for this target: the master's listener reads no line
                on_frame(can_id, data, timestamp)
                return
            previous = rx.line
            rx.line = line
            try:
                on_frame(can_id, data, timestamp)
            finally:
                rx.line = previous
        return deliver

    def on_message_received(self, msg: can.Message) -> None:
        if self.pair._rx_blocked(self.line):
            return
        self.pair._observe(self.line, msg.arbitration_id, bytes(msg.data), msg.timestamp)
        if not self.pair._reaches_application(self.line, msg):
            return
        gating = self.pair.rx_gating
        hold = self.gated and self.line != gating.raw_line
        if hold:
            gating.hold()
        previous, _rx.line = rx_line(), self.line
        try:
            self.target.on_message_received(msg)
        finally:
            _rx.line = previous
            if hold:
                gating.release()

    def on_error(self, exc: Exception) -> None:
        self.target.on_error(exc)


class RedundantBus(can.BusABC):
    """Two lines as one bus (see the module docstring). `open_line(spec, **kwargs)` opens
    one line (base/transport.open_bus)."""

    def __init__(self, spec_a: str, spec_b: str, open_line: Callable[..., can.BusABC], **kwargs):
        from . import frame_sender, frames_sender

        self.specs = (spec_a, spec_b)
        self.line_channels = (line_channel(spec_a), line_channel(spec_b))
        first = open_line(spec_a, **kwargs)
        try:
            second = open_line(spec_b, **kwargs)
        except Exception:
            first.shutdown()
            raise
        self.lines: tuple[can.BusABC, can.BusABC] = (first, second)
        self.faults: tuple[LineFault, LineFault] = (line_fault(spec_a), line_fault(spec_b))
        self.active = 0
        self.tx_router: Callable[[int], int | None] | None = None
        self.rx_observers: list[Callable[[int, int, bytes, float], None]] = []
        self.standby_passes: Callable[[int], bool] | None = None
        self.rx_note: tuple[set[int], set[int]] | None = None
        self.tx_owners: dict[int, object] | None = None
        self.tx_common_line: int | None = None
        self.tx_watch: dict[int, list[Callable[[int, int], None]]] = {}
        self.rx_gating = RxGating(self)
        self.sent = [0, 0]
        self._senders = tuple(frame_sender(line) for line in self.lines)
        self._batch_senders = tuple(frames_sender(line) for line in self.lines)
        self._queue: queue.Queue = queue.Queue()
        self._closing = threading.Event()
        self.channel_info = self.channel_id = f"{spec_a}{PAIR_SEPARATOR}{spec_b}"
        super().__init__(channel=self.channel_info)
        self._readers: list[threading.Thread] = []
        self._start_readers()

    def _start_readers(self) -> None:
        self._readers = [threading.Thread(target=self._read, args=(i,), name=f"can-line-{LINE_NAMES[i]}",
                                          daemon=True) for i in (0, 1)]
        for reader in self._readers:
            reader.start()

    # ------------------------------------------------------------------ receive
    def _rx_blocked(self, line: int) -> bool:
        return self.faults[line].mode in ("cut", "babble", "stuck_dominant") and not self._closing.is_set()

    def _observe(self, line: int, can_id: int, data: bytes, timestamp: float) -> None:
        for observer in self.rx_observers:
            observer(line, can_id, data, timestamp)

    def _reaches_application(self, line: int, msg: can.Message) -> bool:
        """A frame of the standby line reaches the application only if `standby_passes` says so."""
        passes = self.standby_passes
        return line == self.active or passes is None or msg.is_error_frame or passes(msg.arbitration_id)

    def _read(self, line: int) -> None:
        bus = self.lines[line]
        while not self._closing.is_set():
            try:
                msg = bus.recv(_READ_POLL)
            except (can.CanError, OSError, ValueError):
                if self._closing.is_set():
                    return
                continue
            if msg is not None:
                self._arrived(line, msg)

    def _arrived(self, line: int, msg: can.Message) -> None:
        """A frame of `line` for the queue the application reads. Observed here, as it arrives:
        the queue's reader (a Notifier) may run much later on a loaded machine, and the
        master's rule judges a line by when its frames came."""
        if not (self._rx_blocked(line) and not msg.is_error_frame):
            self._observe(line, msg.arbitration_id, bytes(msg.data), msg.timestamp)
        if self._reaches_application(line, msg):
            self._queue.put((line, msg))

    def gate_receivers(self, gate: Callable[[bool], None]) -> None:
        """Receivers that sort frames by rx_line() in gates of their own: `gate(on)` turns them
        on or off (rx_gating.py; the simulator's line selection)."""
        self.rx_gating.attach(gate)

    def set_common_line(self, line: int | None) -> None:
        """The line every node sending through this pair is on (None: they are split)."""
        self.tx_common_line = line
        self.rx_gating.refresh()

    def _recv_internal(self, timeout):
        held = _rx.held
        if held is not None:      # the frame it handed out last has been handled by now
            _rx.held = None
            held.rx_gating.release()
        try:
            line, msg = self._queue.get(timeout=timeout)
        except queue.Empty:
            return None, False
        if self._rx_blocked(line) and not msg.is_error_frame:
            return None, False
        gating = self.rx_gating
        if gating.gate is not None and line != gating.raw_line:
            gating.hold()           # until this reader comes back for the next frame
            _rx.held = self
        _rx.line, _rx.read_from = line, self
        msg.channel = self.line_channels[line]     # a trace of the pair names each frame's line
        return msg, False

    # ------------------------------------------------------------------ transmit
    def _tx_lines(self, can_id: int) -> tuple[int, ...]:
        router = self.tx_router
        if router is None:
            return (self.active,)
        line = router(can_id)
        return (0, 1) if line is None else (line,)

    def _admit(self, line: int, can_id: int, data: bytes) -> bool:
        """The frame enters the line unless the line's fault keeps it off (then what
        receivers see instead is sent)."""
        watchers = self.tx_watch.get(can_id)
        if watchers:
            for watcher in watchers:
                watcher(line, can_id)
        fault = self.faults[line]
        if fault.mode == "ok" or fault.passes():
            self.sent[line] += 1
            return True
        for rid, rdata, error in fault.replacement():
            try:
                if error:
                    self.lines[line].send(can.Message(is_error_frame=True, arbitration_id=0, data=b"",
                                                      is_extended_id=False))
                else:
                    self._senders[line](rid, rdata)
            except can.CanError:
                pass     # a transport that cannot carry error frames: the frame is just lost
        return False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        data = bytes(msg.data)
        for line in self._tx_lines(msg.arbitration_id):
            if self._admit(line, msg.arbitration_id, data):
                self.lines[line].send(msg, timeout)

    def send_frame(self, can_id: int, data: bytes) -> bool:
        """Send one frame; False if a line fault kept it off every line it was sent on. A real
        controller knows this too: a frame nobody received is never acknowledged."""
        master = self.tx_router is None
        if master:                      # the master: the active line only
            line = self.active
        else:                           # a node's frame whose sender is known (its heartbeat, an answer)
            owners = self.tx_owners
            owner = owners.get(can_id) if owners is not None else None
            line = owner.line if owner is not None else None
        if line is not None and self.faults[line].mode == "ok" and can_id not in self.tx_watch:
            self.sent[line] += 1        # _admit's usual answer, without its call
            self._senders[line](can_id, data)
            return True
        if master:
            if self._admit(line, can_id, data):
                self._senders[line](can_id, data)
                return True
            return False
        entered = False
        for line in self._tx_lines(can_id):
            if self._admit(line, can_id, data):
                self._senders[line](can_id, data)
                entered = True
        return entered

    def send_frames(self, frames) -> None:
        """A burst of (can_id, data): each line's share in one write, order kept per line."""
        router, watch, faults = self.tx_router, self.tx_watch, self.faults
        if not isinstance(frames, list):
            frames = list(frames)
        if faults[0].mode == "ok" and faults[1].mode == "ok" and not (
                watch and any(map(watch.__contains__, map(_can_id, frames)))):   # no Python frame per frame
            # the common case, without a call per frame: no fault to apply, nothing watched
            if router is None:
                self.sent[self.active] += len(frames)
                if frames:
                    self._batch_senders[self.active](frames)
                return
            owners = self.tx_owners if self.tx_owners is not None else {}
            common = self.tx_common_line
            if common is not None and all(map(owners.__contains__, map(_can_id, frames))):
                # every sender known and every node on one line: the burst goes there whole
                self.sent[common] += len(frames)
                if frames:
                    self._batch_senders[common](frames)
                return
            per_line: tuple[list, list] = ([], [])
            for frame in frames:
                owner = owners.get(frame[0])
                line = owner.line if owner is not None else router(frame[0])
                if line is None:
                    per_line[0].append(frame)
                    per_line[1].append(frame)
                else:
                    per_line[line].append(frame)
            self.sent[0] += len(per_line[0])
            self.sent[1] += len(per_line[1])
        else:
            per_line = ([], [])
            for can_id, data in frames:
                for line in self._tx_lines(can_id):
                    if self._admit(line, can_id, data):
                        per_line[line].append((can_id, data))
        for line in (0, 1):
            if per_line[line]:
                self._batch_senders[line](per_line[line])

    # ------------------------------------------------------------------ lifecycle
    def shutdown(self) -> None:
        if self._closing.is_set():
            return
        self._closing.set()
        self.rx_gating.detach()
        if _rx.read_from is self:
            _rx.line = _rx.read_from = None
        for reader in self._readers:
            reader.join(2 * _READ_POLL + 0.5)
        for line in self.lines:
            line.shutdown()
        super().shutdown()


class _LineQueue:
    """An in-process line's receive queue, as the senders on that line see it: a frame put
    there goes straight to the pair's queue, tagged with its line, in the sender's thread. No
    reader thread per line: two threads more would wake ten times a second each and lengthen
    every pass of peer_timing's per-thread scan. `queue` (the senders' test for frames still
    waiting, before they deliver inline) is the pair's: order is kept across both lines."""

    def __init__(self, pair: "InlineRedundantBus", line: int):
        self.pair, self.line = pair, line
        self.queue = pair._queue.queue      # queue.Queue keeps its deque for life

    def empty(self) -> bool:
        return self.pair._queue.empty()

    def put(self, msg: can.Message, block: bool = True, timeout: float | None = None) -> None:
        self.pair._arrived(self.line, msg)

    def get(self, block: bool = True, timeout: float | None = None):
        raise queue.Empty     # the line is read through the pair

    def set_handler(self, listener, on_frame) -> None:
        """The function the line's senders call for `listener`'s frames (the in-process bus
        keeps (on_frame, listener) pairs: base/transport add_inline_listener); replaced whole,
        so a sender iterating it sees the old list or the new one."""
        self.inline_handlers = [(on_frame if each is listener else handler, each)
                                for handler, each in self.inline_handlers]
        self.inline_burst = None      # bursts go frame by frame through the new handler


class InlineRedundantBus(RedundantBus):
    """A pair of in-process buses: listeners may take frames inline in the sender's thread."""

    def _start_readers(self) -> None:
        from can.interfaces.virtual import channels_lock

        for i, line in enumerate(self.lines):
            tagged = _LineQueue(self, i)
            with channels_lock:
                line.channel[line.channel.index(line.queue)] = tagged
                line.queue = tagged

    def add_inline_listener(self, listener: can.Listener) -> None:
        for i, line in enumerate(self.lines):
            line_listener = _LineListener(self, i, listener)
            line.add_inline_listener(line_listener)
            if line_listener.gated:
                self.rx_gating.add(line.queue, line_listener)


def open_pair(spec: str, open_line: Callable[..., can.BusABC], **kwargs) -> RedundantBus:
    a, b = split_pair(spec)
    inline = a.partition(":")[0] == "virtual"
    return (InlineRedundantBus if inline else RedundantBus)(a, b, open_line, **kwargs)
