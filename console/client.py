"""Client side of the daemon's command API (one JSON line per request and answer)."""
from __future__ import annotations

import json
import os
import socket
from itertools import count

TYPE_CHECKING = False   # typing itself is ~10 ms of the console's start-up: annotations only
if TYPE_CHECKING:
    from typing import Any

from spacearm.console.errors import CommandFailed
from spacearm.controller.daemon.api_errors import ErrorCode

DEFAULT_API = os.environ.get("SPACEARM_API", "tcp:127.0.0.1:7440")


class ApiClient:
    def __init__(self, address: str = DEFAULT_API, token: str | None = None, timeout: float = 10.0):
        self.address = address
        self.token = token or os.environ.get("SPACEARM_TOKEN")
        self._ids = count(1)
        kind, _, rest = address.partition(":")
        try:
            if kind == "unix":
                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                self._sock.settimeout(timeout)
                self._sock.connect(rest)
            elif kind == "tcp":
                host, _, port = rest.rpartition(":")
                # the host as bytes: the resolver then skips the idna codec, whose import is
                # ~5-10 ms of every command's start on an idle machine (a str host loads it)
                self._sock = socket.create_connection(((host or "127.0.0.1").encode(), int(port)), timeout=timeout)
            else:
                raise CommandFailed(f"bad API address {address!r}: use tcp:HOST:PORT or unix:/path",
                                    ErrorCode.BAD_ARGUMENT)
        except ValueError:
            raise CommandFailed(f"bad API address {address!r}: use tcp:HOST:PORT or unix:/path",
                                ErrorCode.BAD_ARGUMENT) from None
        except OSError as exc:
            raise CommandFailed(f"cannot reach the daemon at {address}: {exc} "
                                "(is `spacearm daemon` running?)", ErrorCode.NO_CONNECTION) from None
        self._stream = self._sock.makefile("rwb")

    def call(self, cmd: str, **args: Any) -> Any:
        request: dict[str, Any] = {"id": next(self._ids), "cmd": cmd, "args": args}
        if self.token:
            request["token"] = self.token
        try:
            self._stream.write(json.dumps(request).encode() + b"\n")
            self._stream.flush()
            line = self._stream.readline()
        except OSError as exc:
            raise CommandFailed(f"lost the connection to the daemon: {exc}", ErrorCode.NO_CONNECTION) from None
        if not line:
            raise CommandFailed("the daemon closed the connection", ErrorCode.NO_CONNECTION)
        try:
            answer = json.loads(line)
        except (json.JSONDecodeError, UnicodeDecodeError):
            answer = None
        if not isinstance(answer, dict) or "ok" not in answer:
            raise CommandFailed(f"{self.address} answered something that is not a spacearm daemon: "
                                f"{line[:60]!r}", ErrorCode.BAD_ANSWER)
        if not answer.get("ok"):
            raise CommandFailed(str(answer.get("error", "refused")), answer.get("code"))
        return answer.get("result")

    def close(self) -> None:
        try:
            self._stream.close()
            self._sock.close()
        except OSError:
            pass

    def __enter__(self) -> "ApiClient":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
