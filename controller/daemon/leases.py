"""The control lease: one console commands the arm, the others may only watch.

`take` hands out a random lease key; every command that moves the arm must carry it.
A console keeps its key between invocations (see console/lease_store.py), so separate
`spacearm move ...` calls from one operator share control while a second operator is
refused until the first releases. There is deliberately no forced takeover over the
API: taking control from a moving console is done at the arm (stop + reset), not remotely.
The holder names who took it (user@host, terminal or web session, pid; console/operate.py), so
`status` tells the operator's terminals and the browser console apart.
"""
from __future__ import annotations

import secrets
import threading
import time

from spacearm.controller.daemon.api_errors import CodedError, ErrorCode
from spacearm.controller.daemon.keys import key_matches


class LeaseError(CodedError):
    default_code = ErrorCode.LEASE_HELD


class ControlLease:
    def __init__(self, clock=time.monotonic) -> None:
        self._lock = threading.Lock()
        self._key: str | None = None
        self._clock = clock
        self.holder = ""
        self.taken_at = 0.0

    def take(self, holder: str, key: str | None = None) -> str:
        """A new key for `holder`; a console that already holds control (it presents the current
        key) gets the same key back: taking what you hold is not an error."""
        with self._lock:
            if self._key is not None and key_matches(key, self._key):
                return self._key
            if self._key is not None:
                raise LeaseError(f"control is held by {self.holder!r}; watch only until it is released")
            self._key = secrets.token_hex(16)
            self.holder, self.taken_at = holder, self._clock()
            return self._key

    def release(self, key: str | None) -> None:
        with self._lock:
            self._check(key)
            self._key, self.holder = None, ""

    def require(self, key: str | None) -> None:
        with self._lock:
            self._check(key)

    def _check(self, key: str | None) -> None:
        if self._key is None:
            raise LeaseError("no console holds control: take it first (`spacearm control take`)", ErrorCode.NO_LEASE)
        if not key_matches(key, self._key):
            raise LeaseError(f"control is held by {self.holder!r}; this console may only watch")

    @property
    def held(self) -> bool:
        return self._key is not None
