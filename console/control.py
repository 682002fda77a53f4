"""The control lease from the console's side: who takes it (identity) and the calls that need it.

Light (the API client and the lease store only): `enable`, `reset`, ... run through here on the
console's fast path (console/quick.py) as well as from typer commands and the web console.
"""
from __future__ import annotations

import os
import socket

TYPE_CHECKING = False   # typing itself is ~10 ms of the console's start-up: annotations only
if TYPE_CHECKING:
    from typing import Any

from spacearm.console import lease_store
from spacearm.console.client import ApiClient
from spacearm.console.errors import CommandFailed
from spacearm.controller.daemon.api_errors import ErrorCode


def controlled_call(client: ApiClient, cmd: str, session: str | None = None, **args: Any) -> Any:
    """Call a command that needs the control lease, taking the lease if nobody holds it."""
    key = lease_store.load(client.address)
    if key is None:
        key = take(client, session)
    try:
        return client.call(cmd, lease=key, **args)
    except CommandFailed as exc:
        if exc.code != ErrorCode.NO_LEASE:
            raise
        # Our stored key is stale (daemon restarted): take control again, once.
        return client.call(cmd, lease=take(client, session), **args)


def holder_identity(session: str | None = None) -> str:
    """Who takes control, as status shows it: user@host, the terminal (or the web session) and
    the pid, so an operator can tell their terminals and the browser console apart."""
    if session is None:
        try:
            session = os.ttyname(0)
        except OSError:
            session = "no tty"
    import getpass      # here: only `control take` and the first lease of a console pay for it
    return f"{getpass.getuser()}@{socket.gethostname()} {session} pid {os.getpid()}"


def take(client: ApiClient, session: str | None = None) -> str:
    """Take control, or keep it: the stored key of this user's consoles is presented, and the
    daemon hands it back when it is the current one (already holding is not an error)."""
    answer = client.call("control.take", holder=holder_identity(session),
                         **({"lease": stored} if (stored := lease_store.load(client.address)) else {}))
    lease_store.save(client.address, answer["lease"])
    return answer["lease"]


ENABLE_WAIT = 5.0   # s: the daemon's own enable timeout is 2 s of cycles, plus a loaded machine

# Why drives may refuse to enable, for the operator (a stop code -> what to do).
ENABLE_HINTS = {
    "enable_timeout": "a drive did not reach 'operation enabled': if a simulator or drive restarted, "
                      "its node stays pre-operational until the daemon is restarted",
    "bootup": "a node restarted: restart the daemon to configure it again",
}


def wait_enabled(client: ApiClient, timeout: float = ENABLE_WAIT) -> dict:
    """Poll status until every drive is enabled; a protective stop instead fails with its reason
    and a hint. Scripts that want the old fire-and-forget use `enable --no-wait`."""
    import time
    deadline = time.monotonic() + timeout
    while True:
        status = client.call("status")
        if status.get("state") == "enabled":
            return status
        if status.get("state") == "stopped":
            stop = status.get("stop") or {}
            hint = ENABLE_HINTS.get(str(stop.get("code")))
            raise CommandFailed(f"enable failed: {stop.get('message') or status.get('stop_reason')}"
                                + (f" ({hint})" if hint else ""), str(stop.get("code") or "protective_stop"))
        if time.monotonic() > deadline:
            raise CommandFailed(f"arm still {status.get('state')} {timeout:.0f} s after enable",
                                ErrorCode.NOT_ENABLED)
        time.sleep(0.05)
