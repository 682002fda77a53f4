"""The daemon's command API: JSON lines over a local socket, served off the control thread.

Each request is one line `{"id": 1, "cmd": "status", "args": {...}, "token": "..."}`; each
answer is one line `{"id": 1, "ok": true, "result": {...}}` or `{"id": 1, "ok": false,
"error": "..."}`. The server runs in its own threads and never touches controller state:
it hands requests to a `handler` callable (the daemon), which answers from a snapshot or
by queueing the command for the next cycle, so a slow or hostile client cannot stall the
20 ms cycle.

Security: it listens on 127.0.0.1 (or a Unix socket) unless `expose=True` is given
explicitly, and then a token is required on every request. Commands that move the arm
need the control lease, which one session holds at a time (see `leases.py`).
"""
from __future__ import annotations

import ipaddress
import json
import logging
import os
import socket
import socketserver
import threading
import time
from dataclasses import dataclass, field
from itertools import count
from pathlib import Path
from typing import Any, Callable

from spacearm.controller.daemon.api_errors import CodedError, ErrorCode
from spacearm.controller.daemon.keys import key_matches

logger = logging.getLogger(__name__)

MAX_REQUEST_BYTES = 64 * 1024
DEFAULT_PORT = 7440


class ApiError(CodedError):
    """A request is refused; the message and its code go back to the client."""
    default_code = ErrorCode.BAD_REQUEST


@dataclass
class Session:
    """One client connection."""
    id: int
    peer: str
    authenticated: bool
    closed: threading.Event = field(default_factory=threading.Event)
    last_seen: float = field(default_factory=time.monotonic)   # last request (command watchdog)


Handler = Callable[[Session, str, dict[str, Any]], Any]
SessionClosed = Callable[[Session], None]


@dataclass(frozen=True)
class ApiAddress:
    kind: str          # "tcp" | "unix"
    host: str = "127.0.0.1"
    port: int = DEFAULT_PORT
    path: str = ""

    @classmethod
    def parse(cls, text: str) -> "ApiAddress":
        """tcp:HOST:PORT, tcp:PORT, unix:/path/to/socket."""
        kind, _, rest = text.partition(":")
        if kind == "unix" and rest:
            return cls("unix", path=rest)
        if kind == "tcp" and rest:
            host, _, port = rest.rpartition(":")
            try:
                return cls("tcp", host=host or "127.0.0.1", port=int(port))
            except ValueError:
                pass
        raise ApiError(f"bad API address {text!r}: use tcp:HOST:PORT or unix:/path", ErrorCode.BAD_ARGUMENT)

    @property
    def is_loopback(self) -> bool:
        if self.kind == "unix":
            return True
        try:
            return ipaddress.ip_address(self.host).is_loopback
        except ValueError:
            return self.host == "localhost"

    def __str__(self) -> str:
        return f"unix:{self.path}" if self.kind == "unix" else f"tcp:{self.host}:{self.port}"


class CommandServer:
    def __init__(self, address: ApiAddress, handler: Handler, on_close: SessionClosed,
                 expose: bool = False, token: str | None = None):
        if not address.is_loopback and not expose:
            raise ApiError(f"refusing to listen on {address}: not loopback; pass --expose "
                           "(and a token) to accept commands from other machines", ErrorCode.BAD_ARGUMENT)
        if expose and not token:
            raise ApiError("an exposed command API needs a token", ErrorCode.BAD_ARGUMENT)
        self.address = address
        self.token = token
        self._handler = handler
        self._on_close = on_close
        self._ids = count(1)
        self.requests = 0
        self.rejected = 0
        self._server = self._make_server()
        # A short poll interval: shutdown() waits for serve_forever's next poll, and a signalled
        # daemon must be down within a second (the default 0.5 s would eat half of it).
        self._thread = threading.Thread(target=self._server.serve_forever, kwargs={"poll_interval": 0.05},
                                        name="command-api", daemon=True)

    def _make_server(self) -> socketserver.BaseServer:
        api = self

        class RequestHandler(socketserver.StreamRequestHandler):
            def handle(self) -> None:
                api._serve_connection(self.connection, self.rfile, self.wfile,
                                      str(self.client_address or "unix"))

        if self.address.kind == "unix":
            path = Path(self.address.path)
            if path.exists():
                path.unlink()

            class UnixServer(socketserver.ThreadingUnixStreamServer):
                daemon_threads = True
            server = UnixServer(str(path), RequestHandler)
            os.chmod(path, 0o600)  # only the daemon's user may command the arm
            return server

        class TcpServer(socketserver.ThreadingTCPServer):
            daemon_threads = True
            allow_reuse_address = True
        return TcpServer((self.address.host, self.address.port), RequestHandler)

    @property
    def bound_port(self) -> int:
        return self._server.server_address[1] if self.address.kind == "tcp" else 0

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        # shutdown() waits for serve_forever to notice: never call it when the server was never
        # started (a daemon whose bring-up failed would hang here for ever).
        if self._thread.is_alive():
            self._server.shutdown()
        self._server.server_close()
        if self.address.kind == "unix":
            Path(self.address.path).unlink(missing_ok=True)

    def _serve_connection(self, connection: socket.socket, rfile, wfile, peer: str) -> None:
        session = Session(next(self._ids), peer, authenticated=self.token is None)
        try:
            while True:
                line = rfile.readline(MAX_REQUEST_BYTES + 1)
                if not line:
                    return
                if len(line) > MAX_REQUEST_BYTES and not line.endswith(b"\n"):
                    self._reply(wfile, None, error=f"request longer than {MAX_REQUEST_BYTES} bytes")
                    return  # the rest of the line is unread garbage: drop the connection
                if line.strip():
                    self._answer(session, line, wfile)
        except (ConnectionError, OSError):
            return
        finally:
            session.closed.set()
            self._on_close(session)

    def _answer(self, session: Session, line: bytes, wfile) -> None:
        self.requests += 1
        request_id = None
        try:
            try:
                request = json.loads(line)
            except (json.JSONDecodeError, UnicodeDecodeError):
                raise ApiError("request is not valid JSON") from None
            if not isinstance(request, dict):
                raise ApiError("request must be a JSON object")
            request_id = request.get("id")
            if not (request_id is None or isinstance(request_id, (int, str))):
                request_id = None
                raise ApiError("id must be an integer or a string")
            if self.token is not None and not session.authenticated:
                given = request.get("token")
                if not key_matches(given, self.token):
                    raise ApiError("missing or wrong token", ErrorCode.UNAUTHORIZED)
                session.authenticated = True
            command = request.get("cmd")
            if not isinstance(command, str) or not command:
                raise ApiError("cmd must be a non-empty string")
            args = request.get("args", {})
            if not isinstance(args, dict):
                raise ApiError("args must be a JSON object")
            result = self._handler(session, command, args)
        except ApiError as exc:
            self.rejected += 1
            self._reply(wfile, request_id, error=str(exc), code=exc.code)
            return
        except Exception as exc:     # a bug in a handler: the console still gets its one answer
            logger.exception("API: request %.200r failed", line)
            self.rejected += 1
            self._reply(wfile, request_id, error=f"internal error: {exc!r}", code=ErrorCode.INTERNAL)
            return
        self._reply(wfile, request_id, result=result)

    @staticmethod
    def _reply(wfile, request_id, result: Any = None, error: str | None = None,
               code: ErrorCode | None = None) -> None:
        answer: dict[str, Any] = {"id": request_id, "ok": error is None}
        if error is None:
            answer["result"] = result
        else:
            answer["error"] = error
            answer["code"] = (code or ErrorCode.INTERNAL).value
        wfile.write(json.dumps(answer, separators=(",", ":")).encode() + b"\n")
        wfile.flush()
