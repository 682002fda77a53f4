"""``loopback:`` transport: a python-can bus whose frames go through the loopback hub (hub.py).

Spec strings (after ``loopback:``)::

    NAME                     channel NAME on the default hub (127.0.0.1:29536, or $SPACEARM_HUB)
    HOST:PORT                channel "default" on the hub at HOST:PORT
    NAME@HOST:PORT           channel NAME on the hub at HOST:PORT

Who starts the hub: if nothing answers and the hub address is a loopback address, the first
client starts one itself (a detached ``python -m spacearm.base.transport.hub`` that exits after
``SPACEARM_HUB_IDLE_EXIT`` seconds, default 30, without clients). Pass ``autostart=False``
(or set ``SPACEARM_HUB_AUTOSTART=0``) to require an explicit ``spacearm hub``; the bus then
raises :class:`HubUnavailableError` naming the address and the command to run.

If the hub goes away while the bus is open, the next send/recv reconnects (starting a hub
again when allowed) for up to ``reconnect_timeout`` seconds; frames sent to or by this node
while it is disconnected are lost, as on a real bus during a bus-off. After that the call
raises ``can.CanOperationError``.
"""
from __future__ import annotations

import logging
import os
import select
import socket
import subprocess
import sys
import threading
import time
from collections import deque

import can

from spacearm.base.runtime.child_process import REPO_ROOT, module_env

from . import wire
from .hub import DEFAULT_HOST, DEFAULT_PORT, is_loopback

log = logging.getLogger("spacearm.transport.loopback")

CONNECT_TIMEOUT = 2.0
AUTOSTART_WAIT = 5.0


class HubUnavailableError(can.CanInitializationError):
    """No loopback hub answers at the given address."""


def default_hub_address() -> tuple[str, int]:
    env = os.environ.get("SPACEARM_HUB", "").strip()
    if env:
        return parse_address(env)
    return DEFAULT_HOST, DEFAULT_PORT


def parse_address(text: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit():
        raise ValueError(f"expected HOST:PORT, got '{text}'")
    host = host.strip("[]") or DEFAULT_HOST
    p = int(port)
    if not 0 < p < 65536:
        raise ValueError(f"port {p} out of range")
    return host, p


def parse_spec(rest: str) -> tuple[str, str, int]:
    """``rest`` is the part after ``loopback:``; returns (channel name, host, port)."""
    if "@" in rest:
        name, _, addr = rest.partition("@")
        host, port = parse_address(addr)
        if not name:
            raise ValueError("empty channel name before '@'")
        return name, host, port
    if ":" in rest or rest.isdigit():
        host, port = parse_address(rest if ":" in rest else f"{DEFAULT_HOST}:{rest}")
        return "default", host, port
    host, port = default_hub_address()
    return rest, host, port


def _autostart_enabled(explicit: bool | None) -> bool:
    if explicit is not None:
        return explicit
    return os.environ.get("SPACEARM_HUB_AUTOSTART", "1").strip().lower() not in ("0", "no", "false", "off")


def spawn_hub(host: str, port: int, idle_exit: float | None = None) -> subprocess.Popen:
    """Start a detached hub process (it outlives this process; it exits when idle)."""
    if idle_exit is None:
        idle_exit = float(os.environ.get("SPACEARM_HUB_IDLE_EXIT", "30"))
    log.info("no loopback hub at %s:%d, starting one (exits after %.0f s idle)", host, port, idle_exit)
    return subprocess.Popen(
        [sys.executable, "-m", "spacearm.base.transport.hub", "--host", host, "--port", str(port),
         "--idle-exit", str(idle_exit), "--quiet-if-running"],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        start_new_session=True, close_fds=True, env=module_env(), cwd=str(REPO_ROOT))


def _wait(sock: socket.socket, event: int, timeout: float | None) -> bool:
    """poll() one socket (select() fails on descriptors >= 1024, which a big process may use)."""
    poller = select.poll()
    poller.register(sock, event | select.POLLERR | select.POLLHUP)
    return bool(poller.poll(None if timeout is None else max(0, int(timeout * 1000 + 0.999))))


class LoopbackBus(can.BusABC):
    """A python-can bus on a loopback hub channel. Thread-safe: one thread may recv while
    others send (as python-can's Notifier and canopen do)."""

    def __init__(self, channel: str = "default", host: str | None = None, port: int | None = None,
                 receive_own_messages: bool = False, autostart: bool | None = None,
                 reconnect_timeout: float = 5.0, connect_timeout: float = CONNECT_TIMEOUT,
                 hub_reports: bool = False, **kwargs):
        dh, dp = default_hub_address()
        self.host = host or dh
        self.port = int(port or dp)
        self.hub_channel = str(channel)
        self.channel_id = self.hub_channel       # as the in-process bus names its channel (CAN trace lines)
        self.receive_own_messages = receive_own_messages
        self.hub_reports = hub_reports      # also receive the hub's own timing reports
        self.autostart = _autostart_enabled(autostart) and is_loopback(self.host)
        self.reconnect_timeout = reconnect_timeout
        self.connect_timeout = connect_timeout
        self.channel_info = f"loopback hub {self.host}:{self.port} channel '{self.hub_channel}'"
        self._send_lock = threading.Lock()
        self._recv_lock = threading.Lock()
        self._conn_lock = threading.Lock()
        self._sock: socket.socket | None = None
        self._generation = 0
        self._inbuf = bytearray()
        self._pending: deque[can.Message] = deque()
        self._poller: select.poll | None = None     # POLLIN on the current connection, made once
        # inline listeners (add_inline_listener): standard data frames go to their on_frame in
        # the receiving thread, as plain values, instead of becoming a can.Message
        self._inline: list[tuple] = []
        self._plain = None
        self._closed = False
        self.client_id: int | None = None
        self.reconnects = 0
        self._connect(first=True)
        super().__init__(channel=self.hub_channel, **kwargs)

    # ------------------------------------------------------------ connection
    def _try_connect_once(self) -> socket.socket:
        sock = socket.create_connection((self.host, self.port), timeout=self.connect_timeout)
        try:
            return self._handshake(sock)
        except OSError as exc:
            sock.close()
            raise wire.ProtocolError(f"connection failed during hello: {exc}") from exc
        except BaseException:
            sock.close()
            raise

    def _handshake(self, sock: socket.socket) -> socket.socket:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.sendall(wire.encode_hello(self.hub_channel, self.receive_own_messages, self.hub_reports))
        # wait for the welcome record: proves the peer is a hub speaking our version
        buf = bytearray()
        deadline = time.monotonic() + self.connect_timeout
        while True:
            records = wire.split_records(buf)
            if records:
                rtype, body = records[0]
                if (rtype != wire.T_WELCOME or body[:len(wire.MAGIC)] != wire.MAGIC
                        or len(body) < len(wire.MAGIC) + 5 or body[len(wire.MAGIC)] != wire.VERSION):
                    raise wire.ProtocolError("peer did not answer like a spacearm loopback hub")
                self.client_id = int.from_bytes(body[len(wire.MAGIC) + 1:len(wire.MAGIC) + 5], "big")
                # frames after the welcome (none expected yet) stay buffered
                rest = bytearray()
                for rt, bd in records[1:]:
                    rest += bytes((len(bd) + 1, rt)) + bd
                self._inbuf = rest + buf
                break
            left = deadline - time.monotonic()
            if left <= 0:
                raise wire.ProtocolError("no answer to hello (is this port a spacearm hub?)")
            sock.settimeout(left)
            chunk = sock.recv(4096)
            if not chunk:
                raise wire.ProtocolError("peer closed the connection during hello")
            buf += chunk
        sock.settimeout(None)
        sock.setblocking(False)
        return sock

    def _connect(self, first: bool = False) -> None:
        """(Re)connect; raises HubUnavailableError (first time) or CanOperationError."""
        deadline = time.monotonic() + (max(AUTOSTART_WAIT, self.connect_timeout) if first else self.reconnect_timeout)
        spawned = False
        last_exc: Exception | None = None
        delay = 0.02
        while True:
            try:
                sock = self._try_connect_once()
            except wire.ProtocolError as exc:
                msg = f"{self.host}:{self.port} is not a spacearm loopback hub: {exc}"
                if first:
                    raise HubUnavailableError(msg) from exc
                last_exc = exc  # a hub restarting may cut the hello short: retry until the deadline
                if time.monotonic() + delay > deadline:
                    raise can.CanOperationError(msg) from exc
                time.sleep(delay)
                delay = min(delay * 2, 0.25)
                continue
            except OSError as exc:
                last_exc = exc
                if self.autostart and not spawned:
                    spawn_hub(self.host, self.port)
                    spawned = True
                elif not self.autostart and first:
                    break
                if time.monotonic() + delay > deadline:
                    break
                time.sleep(delay)
                delay = min(delay * 2, 0.25)
                continue
            poller = select.poll()
            poller.register(sock, select.POLLIN | select.POLLERR | select.POLLHUP)
            self._sock, self._poller = sock, poller
            self._generation += 1
            if not first:
                self.reconnects += 1
                log.warning("%s: reconnected to the hub (frames in flight during the outage are lost)",
                            self.channel_info)
            return
        hint = ("start it with `spacearm hub --port %d` (or `python -m spacearm.base.transport.hub`)" % self.port
                if is_loopback(self.host) else "is the hub running and reachable?")
        msg = f"no loopback CAN hub answers at {self.host}:{self.port} ({last_exc}); {hint}"
        if first:
            raise HubUnavailableError(msg)
        raise can.CanOperationError(msg)

    def _lost(self, generation: int, why: str) -> None:
        """Called when the connection of `generation` failed; reconnect once for everyone."""
        with self._conn_lock:
            if self._closed:
                raise can.CanOperationError(f"{self.channel_info}: bus is shut down")
            if generation != self._generation:
                return  # someone else already reconnected
            log.warning("%s: lost the hub (%s), reconnecting", self.channel_info, why)
            old, self._sock = self._sock, None
            if old is not None:
                old.close()
            self._inbuf = bytearray()
            self._connect(first=False)

    # ------------------------------------------------------------ hot path (base/transport)
    def add_inline_listener(self, listener: can.Listener) -> None:
        """Standard data frames for this bus go to listener.on_frame(can_id, data, timestamp)
        in the thread that receives (the Notifier's), without a can.Message, or all those of
        one read to listener.on_frames([(can_id, data), ...], timestamp) in one call where it
        has that; other frames still reach the Notifier. Same contract as the in-process bus's
        inline listeners."""
        self._inline = self._inline + [(getattr(listener, "on_frame", None), getattr(listener, "on_frames", None),
                                        listener)]
        self._plain = self._deliver

    def _deliver(self, frames: list, timestamp: float) -> None:
        for on_frame, on_frames, listener in self._inline:
            if on_frames is not None:    # a burst in one call (issue 35)
                try:
                    on_frames(frames, timestamp)
                except Exception as exc:   # a receiver's bug must not end the receive thread
                    listener.on_error(exc)
                continue
            for can_id, data in frames:
                try:
                    if on_frame is not None:
                        on_frame(can_id, data, timestamp)
                    else:
                        listener.on_message_received(can.Message(timestamp=timestamp, arbitration_id=can_id,
                                                                 is_extended_id=False, data=data,
                                                                 channel=self.hub_channel, check=False))
                except Exception as exc:   # a receiver's bug must not end the receive thread
                    listener.on_error(exc)

    def send_frame(self, can_id: int, data: bytes) -> None:
        """Send a standard-ID data frame given as plain values (no can.Message)."""
        self.send_frames(((can_id, data),))

    def send_frames(self, frames) -> None:
        """Send standard-ID data frames [(can_id, data), ...] in one write: the hub forwards
        them as one slice and each receiver wakes once for all of them."""
        if self._closed:
            raise can.CanOperationError(f"{self.channel_info}: bus is shut down")
        try:
            record = wire.encode_data_frames(frames)
        except ValueError as exc:
            raise can.CanOperationError(f"cannot send: {exc}") from exc
        self._write(record, None)

    # ------------------------------------------------------------ BusABC
    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self._closed:
            raise can.CanOperationError(f"{self.channel_info}: bus is shut down")
        try:
            record = wire.encode_frame(msg)
        except ValueError as exc:
            raise can.CanOperationError(f"cannot send {msg!r}: {exc}") from exc
        self._write(record, timeout)

    def _write(self, record: bytes, timeout: float | None) -> None:
        """Write whole records, reconnecting once if the connection was lost."""
        deadline = None if timeout is None else time.monotonic() + timeout
        for attempt in (0, 1):
            with self._send_lock:
                sock, gen = self._sock, self._generation
                if sock is None:
                    err = "not connected"
                else:
                    try:
                        self._sendall(sock, record, deadline)
                        return
                    except can.CanOperationError:
                        raise
                    except OSError as exc:
                        err = str(exc)
            if attempt == 0:
                self._lost(gen, f"send failed: {err}")
        raise can.CanOperationError(f"{self.channel_info}: send failed: {err}")

    @staticmethod
    def _sendall(sock: socket.socket, data: bytes, deadline: float | None) -> None:
        view = memoryview(data)
        while view:
            try:
                n = sock.send(view)
                view = view[n:]
                continue
            except (BlockingIOError, InterruptedError):
                pass
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                if len(view) == len(data):
                    raise can.CanOperationError("send timed out (hub not draining)")
                left = 1.0  # never leave half a record on the stream
            _wait(sock, select.POLLOUT, left)

    def _recv_internal(self, timeout: float | None):
        with self._recv_lock:
            if self._pending:
                return self._pending.popleft(), False
            deadline = None if timeout is None else time.monotonic() + timeout
            while True:
                if self._closed:
                    raise can.CanOperationError(f"{self.channel_info}: bus is shut down")
                sock, gen, poller = self._sock, self._generation, self._poller
                if sock is None:
                    self._lost(gen, "not connected")
                    continue
                # wait first, then read: one poll and one recv per wake-up (a read that would
                # block costs a syscall and an exception)
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    left = 0.0
                try:
                    ready = poller.poll(500 if left is None else min(int(left * 1000 + 0.999), 500))
                except (OSError, ValueError):  # closed under us
                    if self._closed:
                        return None, False
                    ready = True
                if not ready:
                    if deadline is not None and time.monotonic() >= deadline:
                        return None, False
                    continue
                try:
                    chunk = sock.recv(65536)
                except (BlockingIOError, InterruptedError):
                    continue
                except OSError as exc:
                    if self._closed:
                        raise can.CanOperationError(f"{self.channel_info}: bus is shut down") from exc
                    self._lost(gen, f"recv failed: {exc}")
                    continue
                if not chunk:
                    self._lost(gen, "hub closed the connection")
                    continue
                if gen != self._generation:
                    continue  # the connection was replaced meanwhile: data of the old one is stale
                self._inbuf += chunk
                try:
                    msgs = wire.decode_stream(self._inbuf, time.time(), self.hub_channel, self._plain)
                except wire.ProtocolError as exc:
                    self._lost(gen, f"corrupt stream from hub: {exc}")
                    continue
                if msgs:
                    if len(msgs) > 1:
                        self._pending.extend(msgs[1:])
                    return msgs[0], False
                if deadline is not None and time.monotonic() >= deadline:
                    return None, False      # only inline frames arrived: they are handled

    def shutdown(self) -> None:
        if self._closed:
            return
        self._closed = True
        with self._conn_lock:
            sock, self._sock = self._sock, None
            if sock is not None:
                try:
                    sock.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass
                sock.close()
        super().shutdown()
