"""The console's fast path: `stop`, `status`, `enable`, `disable`, `reset`, and the commands
of console/daemon_calls.py (`oru pause`, `control take`, `watch`, ...) without typer.

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


# The other commands that only talk to the daemon: words -> (options that take a value, with
# their type; how many positional arguments; whether --json applies; the call). The call gets
# api, token, as_json, the positionals (list) and the options (by name without dashes).
def _daemon_calls() -> dict:
    from spacearm.console import daemon_calls as d
    oru = {("oru", verb): ({}, 0, True, lambda a, t, j, p, o, verb=verb: d.oru_simple(verb, a, t, j))
           for verb in d.ORU_NEEDS_LEASE}
    return {
        **oru,
        ("oru", "status"): ({}, 0, True, lambda a, t, j, p, o: d.oru_status(a, t, j)),
        ("control", "take"): ({}, 0, True, lambda a, t, j, p, o: d.control_take(a, t, j)),
        ("control", "release"): ({}, 0, True, lambda a, t, j, p, o: d.control_release(a, t, j)),
        ("record", "start"): ({}, 1, True, lambda a, t, j, p, o: d.record_start(p[0] if p else None, a, t, j)),
        ("record", "stop"): ({}, 0, True, lambda a, t, j, p, o: d.record_stop(a, t, j)),
        ("watch",): ({"--rate": float, "--count": int}, 0, False,
                     lambda a, t, j, p, o: d.watch(a, t, o.get("rate", 5.0), o.get("count", 0))),
    }


def parse_call(args: list[str]):
    """A no-argument callable running the plain daemon call on the line, else None (typer
    then parses it and gives the usual help and errors)."""
    calls = _daemon_calls()
    words = next((w for w in calls if tuple(args[:len(w)]) == w), None)
    if words is None:
        return None
    value_options, max_positional, json_ok, call = calls[words]
    api = os.environ.get("SPACEARM_API", "tcp:127.0.0.1:7440")
    token = os.environ.get("SPACEARM_TOKEN")
    as_json, positional, options = False, [], {}
    rest = iter(args[len(words):])
    for word in rest:
        name, eq, value = word.partition("=")
        if name in ("--api", "--token") or name in value_options:
            value = value if eq else next(rest, None)
            if not value:
                return None
            if name == "--api":
                api = value
            elif name == "--token":
                token = value
            else:
                try:
                    options[name[2:]] = value_options[name](value)
                except ValueError:
                    return None
        elif word == "--json" and json_ok:
            as_json = True
        elif not word.startswith("-") and len(positional) < max_positional:
            positional.append(word)
        else:
            return None

    def run() -> None:
        from spacearm.console.errors import classify, report
        try:
            call(api, token, as_json, positional, options)
        except Exception as exc:
            known = classify(exc)
            if known is None:
                raise
            raise report(*known, as_json) from None
    return run
