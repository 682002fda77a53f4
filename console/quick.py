"""The console's fast path: `stop`, `status`, `enable`, `disable`, `reset` without typer.

A stop must act at once: these five take only `--api`, `--token` and `--json` (or their
environment variables; `enable` also `--wait/--no-wait`), so they are parsed here and sent with the bare API client; the
interpreter starts, imports a socket and a JSON codec and the request is on its way (typer
alone costs 100-200 ms on this machine). Anything else on the line (`--help`, a typo) goes
to the full typer command, which gives the same answers and the usual errors.
"""
from __future__ import annotations

import json
import os

QUICK_COMMANDS = ("stop", "status", "enable", "disable", "reset")


def parse(args: list[str]) -> tuple[str, str, str | None, bool] | None:
    """(command, api, token, as_json, wait) when the line is a plain quick command, else None."""
    if not args or args[0] not in QUICK_COMMANDS:
        return None
    api = os.environ.get("SPACEARM_API", "tcp:127.0.0.1:7440")
    token = os.environ.get("SPACEARM_TOKEN")
    as_json, wait = False, True
    rest = iter(args[1:])
    for word in rest:
        name, eq, value = word.partition("=")
        if name in ("--api", "--token"):
            value = value if eq else next(rest, None)
            if not value:
                return None                     # let typer say what is missing
            api, token = (value, token) if name == "--api" else (api, value)
        elif word == "--json":
            as_json = True
        elif word in ("--wait", "--no-wait") and args[0] == "enable":
            wait = word == "--wait"
        else:
            return None
    return args[0], api, token, as_json, wait


def run(command: str, api: str, token: str | None, as_json: bool, wait: bool = True) -> None:
    from spacearm.console.client import ApiClient
    from spacearm.console.errors import classify, report

    try:
        with ApiClient(api, token) as client:
            if command in ("stop", "status"):
                result = client.call(command)
            else:
                from spacearm.console.control import controlled_call, wait_enabled
                result = controlled_call(client, command)
                if command == "enable" and wait:
                    result = wait_enabled(client)["state"]
    except Exception as exc:
        known = classify(exc)
        if known is None:
            raise
        raise report(*known, as_json) from None
    if command == "status":
        from spacearm.console.status_view import render_status
        print(json.dumps(result) if as_json else render_status(result))
    elif as_json:
        print(json.dumps({"state": result}))
    else:
        print(f"stopped: arm is {result}" if command == "stop" else f"{command}: arm is {result}")
