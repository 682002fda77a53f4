"""`spacearm oru run|pause|resume|abort|status`: the ORU changeout task flow on a running daemon.

`run` starts the four stages of ORU paper Table 1 (or `--stages 1,2`) from the current
pose and, with --wait (default), follows it subtask by subtask until it ends; a failure ends
in a protective stop whose reason is printed (exit code 1). `abort` needs no control lease
(like `stop`): the flow ends holding the current pose.
"""
from __future__ import annotations

import sys
import time

import typer

from spacearm.console import daemon_calls
from spacearm.console.client import ApiClient
from spacearm.console.commands.operate import API_OPTION, JSON_OPTION, TOKEN_OPTION, WAIT_OPTION, _controlled_call, _emit
from spacearm.console.errors import BadInput, CommandFailed, friendly_errors


def _stages(text: str | None) -> list[int] | None:
    if not text:
        return None
    try:
        return [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise BadInput(f"--stages: expected stage numbers like 1,2 got {text!r}") from None


describe = daemon_calls.oru_describe


def follow(client: ApiClient, as_json: bool) -> dict:
    last = None
    while True:
        status = client.call("oru.status")
        key = (status.get("stage"), status.get("subtask"), status["state"])
        if key != last and not as_json and status.get("subtask") is not None:
            print(f"\r{100 * status['progress']:5.1f} %  stage {status['stage']} subtask {status['subtask']:2d}: "
                  f"{status['title']:<42}", end="", file=sys.stderr)
            last = key
        if status["state"] not in ("running", "paused", "pausing", "resuming") or status.get("pause"):
            if not as_json:
                print(file=sys.stderr)
            return status
        time.sleep(0.2)


def register(app: typer.Typer) -> None:
    oru = typer.Typer(help="ORU changeout task flow (ORU paper Table 1).", no_args_is_help=True)
    app.add_typer(oru, name="oru")

    @oru.command()
    @friendly_errors
    def run(stages: str = typer.Option(None, help="Stages to run, e.g. 1,2 (default: all four)."),
            api: str = API_OPTION, token: str = TOKEN_OPTION, as_json: bool = JSON_OPTION,
            wait: bool = WAIT_OPTION) -> None:
        """Start the changeout from the current pose (the arm must be enabled and still)."""
        args = {"stages": _stages(stages)} if stages else {}      # a typo is refused before connecting
        with ApiClient(api, token) as client:
            result = _controlled_call(client, "oru.run", **args)
            if not wait:
                _emit(result, as_json, "ORU changeout started")
                return
            status = follow(client, as_json)
        _emit(status, as_json, describe(status))
        if status.get("pause"):
            raise CommandFailed(f"ORU changeout paused [{status['pause']['code']}]: {status['pause']['message']} "
                                f"(spacearm oru resume | abort)", "oru_paused")
        if status["state"] != "done":
            raise CommandFailed(f"ORU changeout {status['state']}: {status.get('failure') or 'aborted'}",
                                "oru_failed" if status.get("failure") else "oru_aborted")

    for name, helptext in (("pause", "Hold still; the flow resumes where it was."),
                           ("resume", "Continue a paused changeout."),
                           ("abort", "End the changeout holding the current pose (no lease needed).")):
        def make(verb: str):
            @friendly_errors
            def simple(api: str = API_OPTION, token: str = TOKEN_OPTION, as_json: bool = JSON_OPTION) -> None:
                daemon_calls.oru_simple(verb, api, token, as_json)
            simple.__doc__ = helptext
            return simple
        oru.command(name)(make(name))

    @oru.command()
    @friendly_errors
    def status(api: str = API_OPTION, token: str = TOKEN_OPTION, as_json: bool = JSON_OPTION) -> None:
        """State of the current (or last) changeout: stage, subtask, progress, failure."""
        daemon_calls.oru_status(api, token, as_json)
