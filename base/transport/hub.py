"""The loopback hub: a tiny CAN "bus" between processes on one machine, over TCP.

Every client sends CAN frames to the hub; the hub forwards each frame to every *other*
client on the same named channel, in the order the hub received them (so all receivers see
one and the same bus order, like a real CAN bus), and never back to the sender (unless the
sender asked for its own frames). One thread, one ``selectors`` loop, TCP_NODELAY on every
socket. It binds to 127.0.0.1 unless told otherwise.

Run it with ``spacearm hub`` or ``python -m spacearm.base.transport.hub``; a ``loopback:`` client
also starts one by itself when none answers on a local address (see ``loopback.py``).
"""
from __future__ import annotations

import argparse
import errno
import ipaddress
import logging
import os
import re
import selectors
import signal
import socket
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import can

from . import wire
from .line_faults import LineFault, parse_fault_text
from spacearm.base.canopen import peer_timing
from spacearm.base.runtime.child_process import REPO_ROOT, module_env, readline_within
from spacearm.base.runtime.priority import use_fifo

log = logging.getLogger("spacearm.hub")


def is_loopback(host: str) -> bool:
    """127.0.0.0/8, ::1 or localhost: the only addresses the hub listens on (and autostarts for)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 29536
# A client whose unsent backlog grows past this is not reading: it is cut off (it
# reconnects and logs it) rather than letting the hub grow without bound. ~250k frames.
MAX_BACKLOG = 4 * 1024 * 1024
HELLO_TIMEOUT = 5.0


class _Client:
    __slots__ = ("sock", "addr", "cid", "channel", "receive_own", "hub_reports", "inbuf", "outbuf",
                 "hello_deadline", "writing")

    def __init__(self, sock: socket.socket, addr, cid: int):
        self.sock = sock
        self.addr = addr
        self.cid = cid
        self.channel: str | None = None
        self.receive_own = False
        self.hub_reports = False
        self.inbuf = bytearray()
        self.outbuf = bytearray()
        self.hello_deadline = time.monotonic() + HELLO_TIMEOUT
        self.writing = False


class LoopbackHub:
    """The hub server. ``serve_forever()`` blocks; ``start()`` runs it in a daemon thread."""

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, idle_exit: float = 0.0,
                 max_backlog: int = MAX_BACKLOG, timing_reports: bool = False):
        self.host = host
        self.idle_exit = idle_exit
        self.max_backlog = max_backlog
        self._sel = selectors.DefaultSelector()
        self._lsock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM)
        self._lsock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self._lsock.bind((host, port))
        except OSError:
            self._lsock.close()
            raise
        self._lsock.listen(64)
        self._lsock.setblocking(False)
        self.port = self._lsock.getsockname()[1]
        self._sel.register(self._lsock, selectors.EVENT_READ, None)
        # wake-up pipe so stop() interrupts select() at once
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._sel.register(self._wake_r, selectors.EVENT_READ, "wake")
        self._clients: dict[int, _Client] = {}
        self._channels: dict[str, list[_Client]] = {}
        self._next_id = 1
        self._stop = False
        self._thread: threading.Thread | None = None
        self.frames_forwarded = 0
        # Its own lateness, as a CAN frame (base/canopen/peer_timing.py): the daemon can then
        # say "the hub is starved" rather than blame the nodes. Only to the clients that ask for
        # it in their hello (like a CAN socket's error-frame filter: the nodes never see it);
        # `spacearm hub` turns it on, hubs built inside a test's own process leave it off.
        self.lateness = peer_timing.LatenessMeter() if timing_reports else None
        # Fault injection for tests (hil_tests/faults.py): the hub is the bus, so frames are
        # lost or reordered here. fault_filter(channel, records) -> records to deliver now;
        # disconnect requests cut every TCP client of a channel (they reconnect by themselves).
        self.fault_filter = None
        self._disconnect_requests: list[str] = []
        # Line faults per channel (line_faults.py: cut, babble, ...), from `fault()` or a fault
        # file (`spacearm hub --fault-file PATH`, re-read when it changes): the hub is the
        # line, so a fault here is the same for every client of the channel.
        self.line_faults: dict[str, LineFault] = {}
        self.fault_file: Path | None = None
        self._fault_file_stamp: float | None = None

    # ----------------------------------------------------------------- lifecycle
    @property
    def address(self) -> tuple[str, int]:
        return self.host, self.port

    def start(self) -> "LoopbackHub":
        self._thread = threading.Thread(target=self.serve_forever, name="spacearm-hub", daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout: float = 5.0) -> None:
        self._stop = True
        try:
            self._wake_w.send(b"x")
        except OSError:
            pass
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout)

    def serve_forever(self) -> None:
        log.info("hub listening on %s:%d", self.host, self.port)
        idle_since = time.monotonic()
        tick = idle_since + peer_timing.TICK
        try:
            while not self._stop:
                timeout = 0.5 if self.lateness is None else max(0.0, tick - time.monotonic())
                events = self._sel.select(timeout=timeout)
                for key, mask in events:
                    if key.data is None:
                        self._accept()
                    elif key.data == "wake":
                        try:
                            self._wake_r.recv(64)
                        except OSError:
                            pass
                    else:
                        client = key.data
                        if mask & selectors.EVENT_READ and client.cid in self._clients:
                            self._on_readable(client)
                        if mask & selectors.EVENT_WRITE and client.cid in self._clients:
                            self._flush(client)
                if self.fault_file is not None:
                    self._read_fault_file()
                while self._disconnect_requests:
                    channel = self._disconnect_requests.pop()
                    for client in list(self._channels.get(channel, ())):
                        self._drop(client, "disconnected by fault injection")
                now = time.monotonic()
                if self.lateness is not None and now >= tick:
                    tick = self._timing_tick(tick, now)
                for client in [c for c in self._clients.values() if c.channel is None]:
                    if now > client.hello_deadline:
                        self._drop(client, "no hello within %.0f s" % HELLO_TIMEOUT)
                if self._channels:  # only clients that said hello count as activity
                    idle_since = now
                elif self.idle_exit and now - idle_since > self.idle_exit:
                    log.info("hub idle for %.0f s, exiting", self.idle_exit)
                    break
        finally:
            for client in list(self._clients.values()):
                self._drop(client, "hub shutting down", quiet=True)
            self._sel.close()
            self._lsock.close()
            self._wake_r.close()
            self._wake_w.close()

    def disconnect(self, channel: str) -> None:
        """Cut every client of `channel` (thread-safe; done by the hub thread at once)."""
        self._disconnect_requests.append(channel)
        try:
            self._wake_w.send(b"x")
        except OSError:
            pass

    def fault(self, channel: str, mode: str, loss: float | None = None) -> None:
        """Inject a line fault on `channel` ("ok" ends it); raises LineFaultError."""
        fault = self.line_faults.get(channel) or LineFault(channel, seed=sum(channel.encode()))
        fault.set(mode, loss)
        if fault.active:
            self.line_faults[channel] = fault
        else:
            self.line_faults.pop(channel, None)
        log.warning("line fault on channel '%s': %s", channel, fault.describe())

    def _read_fault_file(self) -> None:
        """Lines "CHANNEL MODE [LOSS]"; a channel not named has no fault. A bad line is one log line."""
        try:
            stamp = self.fault_file.stat().st_mtime_ns
        except OSError:
            stamp = None
        if stamp == self._fault_file_stamp:
            return
        self._fault_file_stamp = stamp
        text = self.fault_file.read_text() if stamp is not None else ""
        wanted, problems = parse_fault_text(text)
        for problem in problems:
            log.warning("%s:%s (line ignored)", self.fault_file, problem)
        for channel in set(self.line_faults) - set(wanted):
            self.fault(channel, "ok")
        for channel, (mode, loss) in wanted.items():
            self.fault(channel, mode, loss)

    def _apply_line_fault(self, channel: str, records: list[bytes]) -> list[bytes]:
        fault = self.line_faults.get(channel)
        if fault is None:
            return records
        out = []
        for record in records:
            if fault.passes():
                out.append(record)
                continue
            for can_id, data, error in fault.replacement():
                out.append(wire.encode_frame(can.Message(arbitration_id=can_id, data=data, is_extended_id=False,
                                                         is_error_frame=error)))
        return out

    # ----------------------------------------------------------------- internals
    def _timing_tick(self, tick: float, now: float) -> float:
        """One timer tick: how late it came; the report to every channel when due. Returns the next tick."""
        self.lateness.woke(now - tick, now)
        if self.lateness.due(now):
            record = wire.encode_frame(can.Message(arbitration_id=peer_timing.HUB_COB_ID,
                                                   data=self.lateness.report(now), is_extended_id=False))
            for dest in [c for c in self._clients.values() if c.hub_reports and c.channel is not None]:
                if len(dest.outbuf) + len(record) <= self.max_backlog:
                    dest.outbuf += record
                    self._flush(dest)
        return now + peer_timing.TICK

    def _accept(self) -> None:
        while True:
            try:
                sock, addr = self._lsock.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:  # EMFILE etc.: keep serving the others
                log.warning("accept failed: %s", exc)
                return
            sock.setblocking(False)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            client = _Client(sock, addr, self._next_id)
            self._next_id += 1
            self._clients[client.cid] = client
            self._sel.register(sock, selectors.EVENT_READ, client)

    def _drop(self, client: _Client, reason: str, quiet: bool = False) -> None:
        if self._clients.pop(client.cid, None) is None:
            return
        (log.debug if quiet else log.info)("client %d %s (%s) dropped: %s", client.cid, client.addr,
                                           client.channel, reason)
        try:
            self._sel.unregister(client.sock)
        except (KeyError, ValueError):
            pass
        client.sock.close()
        if client.channel is not None:
            members = self._channels.get(client.channel, [])
            if client in members:
                members.remove(client)
            if not members:
                self._channels.pop(client.channel, None)

    def _on_readable(self, client: _Client) -> None:
        try:
            data = client.sock.recv(65536)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            self._drop(client, f"read error: {exc}")
            return
        if not data:
            self._drop(client, "disconnected", quiet=True)
            return
        client.inbuf += data
        if client.channel is not None and self.fault_filter is None and client.channel not in self.line_faults:
            self._forward_frames(client)
            return
        if client.channel is None and len(client.inbuf) >= 2 and client.inbuf[1] != wire.T_HELLO:
            # Not our protocol (e.g. a console's JSON request sent to the hub's port by mistake):
            # drop it now rather than at the hello deadline, so the sender fails at once.
            self._drop(client, "protocol error: expected hello")
            return
        try:
            records = wire.split_records(client.inbuf)
        except wire.ProtocolError as exc:
            self._drop(client, f"protocol error: {exc}")
            return
        if len(client.inbuf) > 512:  # cannot happen with a valid stream (records are < 256 bytes)
            self._drop(client, "protocol error: oversized record")
            return
        out: list[bytes] = []
        for rtype, body in records:
            if client.channel is None:
                if rtype != wire.T_HELLO or not self._hello(client, body):
                    self._drop(client, "protocol error: expected hello")
                    return
                continue
            if rtype != wire.T_FRAME:
                self._drop(client, f"protocol error: unexpected record type {rtype}")
                return
            try:
                wire.check_frame_body(body)
            except wire.ProtocolError as exc:
                self._drop(client, f"protocol error: {exc}")
                return
            out.append(bytes((len(body) + 1, wire.T_FRAME)) + body)
        if self.fault_filter is not None:
            out = self.fault_filter(client.channel, out)
        out = self._apply_line_fault(client.channel, out)
        if out:
            self._fan_out(client, b"".join(out), len(out))

    def _forward_frames(self, client: _Client) -> None:
        """The hot path: the complete FRAME records at the start of the client's buffer are
        checked in place and forwarded as one slice (one write per receiver per read, however
        many frames the sender batched), not split into a bytes object per record."""
        try:
            end, count = wire.frames_end(client.inbuf)
        except wire.ProtocolError as exc:
            self._drop(client, f"protocol error: {exc}")
            return
        if len(client.inbuf) - end > 512:  # cannot happen with a valid stream (records are < 256 bytes)
            self._drop(client, "protocol error: oversized record")
            return
        if count:
            blob = bytes(client.inbuf[:end])
            del client.inbuf[:end]
            self._fan_out(client, blob, count)

    def _hello(self, client: _Client, body: bytes) -> bool:
        if len(body) < len(wire.MAGIC) + 3 or body[:len(wire.MAGIC)] != wire.MAGIC:
            return False
        version = body[len(wire.MAGIC)]
        if version != wire.VERSION:
            log.warning("client %d speaks protocol version %d, hub %d", client.cid, version, wire.VERSION)
            return False
        options = body[len(wire.MAGIC) + 1]
        try:
            channel = body[len(wire.MAGIC) + 2:].decode("utf-8")
        except UnicodeDecodeError:
            return False
        client.channel = channel
        client.receive_own = bool(options & wire.OPT_RECEIVE_OWN)
        client.hub_reports = bool(options & wire.OPT_HUB_REPORTS)
        self._channels.setdefault(channel, []).append(client)
        client.outbuf += wire.encode_welcome(client.cid)
        self._flush(client)
        log.info("client %d %s joined channel '%s'", client.cid, client.addr, channel)
        return True

    def _fan_out(self, sender: _Client, blob: bytes, nframes: int) -> None:
        self.frames_forwarded += nframes
        for dest in list(self._channels.get(sender.channel, ())):
            if dest is sender and not dest.receive_own:
                continue
            if dest.cid not in self._clients:
                continue
            if len(dest.outbuf) + len(blob) > self.max_backlog:
                self._drop(dest, "not reading (backlog over %d bytes)" % self.max_backlog)
                continue
            dest.outbuf += blob
            self._flush(dest)

    def _flush(self, client: _Client) -> None:
        if client.outbuf:
            try:
                sent = client.sock.send(client.outbuf)
            except (BlockingIOError, InterruptedError):
                sent = 0
            except OSError as exc:
                self._drop(client, f"write error: {exc}")
                return
            del client.outbuf[:sent]
        want_write = bool(client.outbuf)
        if want_write != client.writing:
            client.writing = want_write
            events = selectors.EVENT_READ | (selectors.EVENT_WRITE if want_write else 0)
            self._sel.modify(client.sock, events, client)


class HubProcess:
    """A hub in its own process on a free 127.0.0.1 port (for the session or one test)."""

    def __init__(self, port: int = 0, ready_timeout: float = 15.0, rt_priority: int = 0,
                 fault_file: Path | None = None):
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "spacearm.base.transport.hub", "--host", "127.0.0.1", "--port", str(port),
             "--rt-priority", str(rt_priority), *(["--fault-file", str(fault_file)] if fault_file else [])],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=str(REPO_ROOT), env=module_env())
        line = readline_within(self.proc, ready_timeout)
        m = re.search(r"listening on ([\d.]+):(\d+)", line or "")
        if not m:
            self.stop()
            err = self.proc.stderr.read() if self.proc.stderr else ""
            raise RuntimeError(f"loopback hub did not start: {line!r} {err[-2000:]}")
        self.host, self.port = m.group(1), int(m.group(2))
        # keep draining its stderr (logging) so the pipe never fills
        threading.Thread(target=self._drain, daemon=True).start()

    def _drain(self):
        try:
            for _ in self.proc.stderr:
                pass
        except (OSError, ValueError):
            pass

    @property
    def address(self) -> str:
        return f"{self.host}:{self.port}"

    def spec(self, name: str | None = None) -> str:
        return f"loopback:{name or 'hil-' + uuid.uuid4().hex[:10]}@{self.address}"

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="spacearm-hub", description=__doc__.splitlines()[0])
    parser.add_argument("--host", default=DEFAULT_HOST, help="address to bind (default 127.0.0.1)")
    parser.add_argument("--port", type=int, default=DEFAULT_PORT, help=f"TCP port (default {DEFAULT_PORT}; 0 = any)")
    parser.add_argument("--idle-exit", type=float, default=0.0,
                        help="exit after this many seconds without clients (0 = never)")
    parser.add_argument("--quiet-if-running", action="store_true",
                        help="exit 0 silently if the port is already taken (used by auto-start)")
    parser.add_argument("--rt-priority", type=int, default=0,
                        help="SCHED_FIFO priority 1..99 (0 = normal scheduling; base/runtime/priority.py)")
    parser.add_argument("--fault-file", type=Path, default=None,
                        help='line faults, re-read when changed: lines "CHANNEL MODE [LOSS]" (line_faults.py)')
    parser.add_argument("-v", "--verbose", action="store_true")
    args = parser.parse_args(argv)
    return run(args.host, args.port, args.idle_exit, args.quiet_if_running, args.verbose, args.rt_priority,
               args.fault_file)


def run(host: str, port: int, idle_exit: float = 0.0, quiet_if_running: bool = False,
        verbose: bool = False, rt_priority: int = 0, fault_file: Path | None = None) -> int:
    if rt_priority:
        problem = use_fifo(rt_priority)     # before the serving thread starts: it inherits it
        if problem:
            print(f"spacearm hub: {problem}", file=sys.stderr)
    logging.basicConfig(level=logging.DEBUG if verbose else logging.INFO,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    # Failures are one line with the console's error[CODE] prefix (console/errors.py) and exit 2.
    if not is_loopback(host):
        # anyone who reaches the address could put frames on the arm's bus: no token, no checks
        print(f"error[bad_argument]: spacearm hub: --host {host}: the hub listens on loopback only "
              "(127.0.0.1 or ::1); reach it from elsewhere through an SSH tunnel", file=sys.stderr)
        return 2
    try:
        hub = LoopbackHub(host, port, idle_exit=idle_exit, timing_reports=True)
    except OSError as exc:
        if exc.errno == errno.EADDRINUSE:
            if quiet_if_running:
                return 0
            print(f"error[address_in_use]: spacearm hub: {host}:{port} is already in use (another hub running?)",
                  file=sys.stderr)
            return 2
        print(f"error[bind_failed]: spacearm hub: cannot bind {host}:{port}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    hub.fault_file = fault_file
    # SIGINT too, explicitly: a hub started with `&` from a script inherits SIGINT ignored, and
    # Python then installs no KeyboardInterrupt handler (it ignored Ctrl-C / kill -INT for 608 s).
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: hub.stop(0))
    print(f"spacearm hub listening on {hub.host}:{hub.port} (pid {os.getpid()})", flush=True)
    try:
        hub.serve_forever()
    except KeyboardInterrupt:
        pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
