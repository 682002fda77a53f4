"""The control lease from the console's side: who takes it (identity) and the calls that need it.

Light (the API client and the lease store only): `enable`, `reset`, ... run through here on the
console's fast path (console/quick.py) as well as from typer commands and the web console.
"""
from __future__ import annotations

import getpass
import os
import socket
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
    return f"{getpass.getuser()}@{socket.gethostname()} {session} pid {os.getpid()}"


def take(client: ApiClient, session: str | None = None) -> str:
    """Take control, or keep it: the stored key of this user's consoles is presented, and the
    daemon hands it back when it is the current one (already holding is not an error)."""
    answer = client.call("control.take", holder=holder_identity(session),
                         **({"lease": stored} if (stored := lease_store.load(client.address)) else {}))
    lease_store.save(client.address, answer["lease"])
    return answer["lease"]
