"""One factory for CAN buses, named by a string (as python-can does with interfaces).

    virtual:NAME                 python-can's in-process virtual bus (the embedded default)
    loopback:NAME                multi-process bus through the loopback hub on 127.0.0.1:29536
                                 (or $SPACEARM_HUB); the first client starts the hub if none runs
    loopback:HOST:PORT           channel "default" on the hub at HOST:PORT
    loopback:NAME@HOST:PORT      channel NAME on the hub at HOST:PORT
    socketcan:CHANNEL            Linux SocketCAN (vcan0 in tests, can0 on hardware)
    SPEC_A+SPEC_B                a redundant pair of lines of one transport, e.g.
                                 virtual:arm-a+virtual:arm-b (redundant.py)

No transport delivers a node's own frames back to it (receive_own_messages=False), like a
real CAN controller.
"""
from __future__ import annotations

import queue
import sys
import threading
import time

import can

TRANSPORTS = ("virtual", "loopback", "socketcan")


class BusSpecError(ValueError):
    """The --bus string does not name a known transport."""


def parse_bus_spec(spec: str) -> tuple[str, str]:
    """Split 'KIND:REST' and check KIND; raises BusSpecError."""
    if not isinstance(spec, str):
        raise BusSpecError(f"bus spec must be a string, got {type(spec).__name__}")
    kind, sep, rest = spec.strip().partition(":")
    if not sep or not rest:
        raise BusSpecError(f"bus '{spec}': expected KIND:NAME, e.g. virtual:arm, loopback:arm or socketcan:vcan0")
    if kind not in TRANSPORTS:
        raise BusSpecError(f"bus '{spec}': unknown transport '{kind}' (known: {', '.join(TRANSPORTS)})")
    return kind, rest


def _checked(base: type) -> type:
    """A subclass of a python-can bus whose send() refuses frames no CAN controller could put
    on the wire (python-can's virtual bus accepts anything), with a can.CanOperationError."""

    class Checked(base):
        def send(self, msg: can.Message, timeout: float | None = None) -> None:
            from .wire import encode_frame

            try:
                encode_frame(msg)
            except ValueError as exc:
                raise can.CanOperationError(f"cannot send {msg!r}: {exc}") from exc
            super().send(msg, timeout)

    Checked.__name__ = Checked.__qualname__ = "Checked" + base.__name__
    return Checked


# A burst of frames arriving while the application is busy must not overflow the kernel's
# per-socket receive queue (the default ~200 KiB holds only a few hundred CAN skbs).
SOCKETCAN_RCVBUF = 8 * 1024 * 1024


def _enlarge_rcvbuf(bus: can.BusABC, size: int = SOCKETCAN_RCVBUF) -> None:
    import socket

    sock = getattr(bus, "socket", None)
    if sock is None:
        return
    # SO_RCVBUFFORCE (33 on Linux; Python's socket module does not name it) needs
    # CAP_NET_ADMIN; otherwise SO_RCVBUF is capped by net.core.rmem_max (~555 frames by default).
    force = getattr(socket, "SO_RCVBUFFORCE", 33 if sys.platform.startswith("linux") else None)
    for opt in (force, socket.SO_RCVBUF):
        if opt is None:
            continue
        try:
            sock.setsockopt(socket.SOL_SOCKET, opt, size)
            return
        except OSError:
            continue


class _FastVirtual:
    """python-can's VirtualBus, made cheap enough for lockstep runs.

    * Its send() deep-copies every frame once per receiver (~25 us each); a CAN frame is a few
      plain fields, so each receiver gets a new Message built from them instead.
    * A receiver may register *inline* listeners (`add_inline_listener`): frames for it are
      then handled in the sender's thread, during send(), instead of waking the receiver's
      Notifier thread. In a lockstep cycle this removes every thread hop (SYNC -> simulated
      nodes -> TPDOs -> controller), the largest cost left. Frames fall back to the receiver's
      queue (and its Notifier) when delivery to it is already running in this thread or
      frames are still queued for it, so order is kept and nothing recurses.
    * `send_frame(can_id, data)` is the hot path for standard data frames (SYNC, PDOs,
      heartbeats): no Message for the sender, and an inline listener that has
      `on_frame(can_id, data, timestamp)` gets the frame as plain values, so a cycle's ~40
      frames create no Message objects at all. A Message is built only for a queued receiver.

    * `send_frames([(can_id, data), ...])` sends a burst (a cycle's RPDOs, a SYNC's TPDOs) as
      the loopback hub forwards one: the taps see the whole burst first, then each receiver
      takes it whole, in one call where its one inline listener has `on_frames(frames,
      timestamp)` (issue 35: one call a burst instead of one per frame and receiver). A frame
      a receiver sends in answer follows the burst, as on the loopback bus.

    * A passive observer (a trace) registers as a *tap* (`add_tap`): it sees every frame on the
      channel, first, in the sender's thread, and its bus receives nothing else. No queue and
      no re-entrancy guard: ~0.5 us less per frame than an inline listener (issue 35).

    Listeners called inline must not take a lock the sending code may hold; the simulator's
    and the ArmNetwork's listeners only take their own state locks.
    """

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._taps = _channel_taps(self.channel_id)
        self._tap: can.Listener | None = None

    def add_tap(self, listener: can.Listener) -> None:
        """`listener` sees every frame sent on this channel from now on, in the sender's thread
        before any receiver (so in wire order, a request before the answers a receiver sends
        inline): frames from send_frame as on_frame(can_id, data, timestamp), others as
        on_message_received(msg). It must not send or take a lock a sender may hold. This bus
        stops receiving; shutdown() removes the tap."""
        from can.interfaces.virtual import channels_lock

        with channels_lock:
            self.channel.remove(self.queue)
        self._tap = listener
        self._taps.add(listener)

    def shutdown(self) -> None:
        if self._tap is not None and self._open:
            from can.interfaces.virtual import channels, channels_lock

            self._taps.remove(self._tap)
            self._open = False           # python-can's shutdown would remove the queue add_tap removed
            with channels_lock:
                if not self.channel and channels.get(self.channel_id) is self.channel:
                    del channels[self.channel_id]
        super().shutdown()

    def add_inline_listener(self, listener: can.Listener) -> None:
        self.queue.inline_listeners = getattr(self.queue, "inline_listeners", []) + [listener]
        # for send_frame: each listener's plain-value handler, looked up once here
        self.queue.inline_handlers = getattr(self.queue, "inline_handlers", []) + [
            (getattr(listener, "on_frame", None), listener)]
        # for send_frames: a burst in one call, where this queue's only listener takes bursts
        listeners = self.queue.inline_listeners
        self.queue.inline_burst = getattr(listener, "on_frames", None) if len(listeners) == 1 else None

    def send_frame(self, can_id: int, data: bytes) -> None:
        """Send a standard-ID data frame given as plain values (the same frame send() would put
        on the bus for can.Message(arbitration_id=can_id, data=data, is_extended_id=False))."""
        self.send_frames(((can_id, data),))

    def send_frames(self, frames) -> None:
        """Send standard-ID data frames [(can_id, data), ...] as one burst (class docstring):
        one timestamp, the taps first, then each receiver the whole burst in order."""
        if not self._open:
            raise can.CanOperationError("Cannot operate on a closed bus")
        for can_id, data in frames:
            if not 0 <= can_id <= 0x7FF or len(data) > 8:
                raise can.CanOperationError(f"cannot send frame 0x{can_id:X} with {len(data)} bytes: "
                                            "not a standard CAN data frame")
        timestamp = time.time()
        taps = self._taps
        for on_frames in taps.on_frames:
            try:
                on_frames(frames, timestamp)
            except Exception as exc:   # a tap's bug must not fail the sender
                taps.failed(on_frames, exc)
        own = None if self.receive_own_messages else self.queue
        try:
            active = _inline.active       # this thread's receivers in delivery (_enter_inline)
        except AttributeError:
            active = _inline.active = set()
        for bus_queue in self.channel:
            if bus_queue is own:
                continue
            handlers = getattr(bus_queue, "inline_handlers", None)
            if handlers and not bus_queue.queue and bus_queue not in active:   # deque length: no lock
                active.add(bus_queue)
                try:
                    burst = getattr(bus_queue, "inline_burst", None)
                    if burst is not None:
                        try:
                            burst(frames, timestamp)
                        except Exception as exc:   # a receiver's bug must not fail the sender
                            handlers[0][1].on_error(exc)
                        continue
                    for can_id, data in frames:
                        self._deliver(handlers, can_id, data, timestamp, bus_queue)
                finally:
                    active.discard(bus_queue)
                continue
            for can_id, data in frames:
                bus_queue.put(self._copy(can_id, data, timestamp, bus_queue))

    def _deliver(self, handlers, can_id: int, data: bytes, timestamp: float, bus_queue) -> None:
        for on_frame, listener in handlers:
            try:
                if on_frame is not None:
                    on_frame(can_id, data, timestamp)
                else:
                    listener.on_message_received(self._copy(can_id, data, timestamp, bus_queue))
            except Exception as exc:   # a receiver's bug must not fail the sender
                listener.on_error(exc)

    def _copy(self, can_id: int, data: bytes, timestamp: float, bus_queue) -> can.Message:
        return can.Message(timestamp=timestamp, arbitration_id=can_id, is_extended_id=False,
                           channel=self.channel_id, dlc=len(data), data=data,
                           is_rx=bus_queue is not self.queue, check=False)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self._check_if_open()
        timestamp = msg.timestamp if self.preserve_timestamps else time.time()
        data = bytes(msg.data)
        if self._taps.listeners:
            self._tap_message(msg, timestamp, data)
        all_sent = True
        for bus_queue in list(self.channel):
            if bus_queue is self.queue and not self.receive_own_messages:
                continue
            copy = can.Message(timestamp=timestamp, arbitration_id=msg.arbitration_id,
                               is_extended_id=msg.is_extended_id, is_remote_frame=msg.is_remote_frame,
                               is_error_frame=msg.is_error_frame, channel=self.channel_id, dlc=msg.dlc,
                               data=data, is_fd=msg.is_fd, is_rx=bus_queue is not self.queue,
                               bitrate_switch=msg.bitrate_switch, error_state_indicator=msg.error_state_indicator,
                               check=False)
            listeners = getattr(bus_queue, "inline_listeners", None)
            if listeners and bus_queue.empty() and _enter_inline(bus_queue):
                try:
                    for listener in listeners:
                        try:
                            listener.on_message_received(copy)
                        except Exception as exc:   # a receiver's bug must not fail the sender
                            listener.on_error(exc)
                finally:
                    _leave_inline(bus_queue)
                continue
            try:
                bus_queue.put(copy, block=True, timeout=timeout)
            except queue.Full:
                all_sent = False
        if not all_sent:
            raise can.CanOperationError("Could not send message to one or more recipients")

    def _tap_message(self, msg: can.Message, timestamp: float, data: bytes) -> None:
        seen = can.Message(timestamp=timestamp, arbitration_id=msg.arbitration_id, is_extended_id=msg.is_extended_id,
                           is_remote_frame=msg.is_remote_frame, is_error_frame=msg.is_error_frame,
                           channel=self.channel_id, dlc=msg.dlc, data=data, is_fd=msg.is_fd, is_rx=True,
                           bitrate_switch=msg.bitrate_switch, error_state_indicator=msg.error_state_indicator,
                           check=False)
        for listener in self._taps.listeners:
            try:
                listener.on_message_received(seen)
            except Exception as exc:   # a tap's bug must not fail the sender
                listener.on_error(exc)


class _Taps:
    """A channel's taps, replaced whole on a change so a sender iterating them never sees a
    half-changed sequence (senders run in any thread)."""

    def __init__(self) -> None:
        self.listeners: tuple[can.Listener, ...] = ()
        self.on_frames: tuple = ()
        self._lock = threading.Lock()

    def add(self, listener: can.Listener) -> None:
        with self._lock:
            self._set(self.listeners + (listener,))

    def remove(self, listener: can.Listener) -> None:
        with self._lock:
            self._set(tuple(t for t in self.listeners if t is not listener))

    def failed(self, on_frames, exc: Exception) -> None:
        for listener, handler in zip(self.listeners, self.on_frames):
            if handler is on_frames:
                listener.on_error(exc)

    def _set(self, listeners: tuple) -> None:
        self.listeners = listeners
        self.on_frames = tuple(getattr(t, "on_frames", None) or _burst_of(t.on_frame) for t in listeners)


def _burst_of(on_frame):
    """A tap that takes frames one by one, given a burst: each frame, in order."""
    def on_frames(frames, timestamp: float) -> None:
        for can_id, data in frames:
            on_frame(can_id, data, timestamp)
    return on_frames


_TAPS: dict = {}
_TAPS_LOCK = threading.Lock()


def _channel_taps(channel_id) -> _Taps:
    """The taps of a channel (kept while the process runs: a few bytes per channel name)."""
    with _TAPS_LOCK:
        return _TAPS.setdefault(channel_id, _Taps())


def frame_sender(bus: can.BusABC):
    """The cheapest way to send a standard data frame on `bus`: send(can_id, data).
    The in-process bus takes plain values; other transports get the can.Message they need."""
    fast = getattr(bus, "send_frame", None)
    if fast is not None:
        return fast
    message = can.Message

    def send(can_id: int, data: bytes) -> None:
        bus.send(message(arbitration_id=can_id, data=data, is_extended_id=False))
    return send


def frames_sender(bus: can.BusABC):
    """The cheapest way to send a burst of standard data frames on `bus`:
    send([(can_id, data), ...]). The loopback bus writes them in one record stream (one
    syscall, one wake-up per receiver); other buses send them one by one."""
    batch = getattr(bus, "send_frames", None)
    if batch is not None:
        return batch
    one = frame_sender(bus)

    def send(frames) -> None:
        for can_id, data in frames:
            one(can_id, data)
    return send


_inline = threading.local()


def _enter_inline(bus_queue) -> bool:
    """Mark `bus_queue`'s inline delivery as running in this thread (False if it already is).
    The set holds the receive queues themselves (identity-hashed): one call less per frame
    than their id()."""
    active = getattr(_inline, "active", None)
    if active is None:
        active = _inline.active = set()
    if bus_queue in active:
        return False
    active.add(bus_queue)
    return True


def _leave_inline(bus_queue) -> None:
    _inline.active.discard(bus_queue)


_CHECKED: dict[str, type] = {}


def _bus_class(kind: str) -> type:
    if kind not in _CHECKED:
        if kind == "virtual":
            from can.interfaces.virtual import VirtualBus

            base = type("FastVirtualBus", (_FastVirtual, VirtualBus), {})
        else:
            from can.interfaces.socketcan import SocketcanBus as base
        _CHECKED[kind] = _checked(base)
    return _CHECKED[kind]


def open_bus(spec: str, **kwargs) -> can.BusABC:
    """Open the bus named by `spec`; extra keyword arguments go to the python-can bus.

    Raises BusSpecError for a malformed spec, and a can.CanInitializationError subclass when
    the transport is fine but cannot be opened (no hub, no such interface, no kernel CAN).
    hub_reports=True: on a loopback hub, also receive the hub's own timing reports (other
    transports have no hub; the option is dropped).
    """
    hub_reports = kwargs.pop("hub_reports", False)
    from .redundant import PAIR_SEPARATOR, open_pair, split_pair

    if isinstance(spec, str) and PAIR_SEPARATOR in spec:
        try:
            split_pair(spec)
        except ValueError as exc:
            raise BusSpecError(str(exc)) from None
        return open_pair(spec, open_bus, hub_reports=hub_reports, **kwargs)
    kind, rest = parse_bus_spec(spec)
    if kind == "virtual":
        # receive_own_messages=False: like a real controller, a node does not see its own frames.
        return _bus_class("virtual")(channel=rest, **kwargs)
    if kind == "loopback":
        from .loopback import LoopbackBus, parse_spec

        try:
            name, host, port = parse_spec(rest)
        except ValueError as exc:
            raise BusSpecError(f"bus '{spec}': {exc}") from exc
        return LoopbackBus(channel=name, host=host, port=port, hub_reports=hub_reports, **kwargs)
    # socketcan
    if "/" in rest or len(rest) > 15 or any(c.isspace() for c in rest):
        raise BusSpecError(f"bus '{spec}': '{rest}' is not a network interface name")
    try:
        bus = _bus_class("socketcan")(channel=rest, **kwargs)
        _enlarge_rcvbuf(bus)
        return bus
    except can.CanInitializationError:
        raise
    except OSError as exc:
        raise can.CanInitializationError(
            f"bus '{spec}': cannot open SocketCAN interface '{rest}': {exc} "
            f"(does it exist? `ip link show {rest}`; for tests: `modprobe vcan && "
            f"ip link add dev {rest} type vcan && ip link set up {rest}`)") from exc
