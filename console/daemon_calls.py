"""The bodies of the console commands that only talk to the daemon, without typer.

`oru pause|resume|abort|status`, `control take|release`, `record start|stop` and `watch` run
from here both on the fast path (console/quick.py: no typer, whose parameter coercion alone
imports pydantic) and as typer commands (console/commands/operate.py, oru.py), so the two
give the same answers. Imports: the API client, the lease store, the status view.
"""
from __future__ import annotations

import json
import time

TYPE_CHECKING = False   # typing itself is ~10 ms of the console's start-up: annotations only
if TYPE_CHECKING:
    from typing import Any

from spacearm.console import lease_store
from spacearm.console.client import ApiClient
from spacearm.console.control import controlled_call, take


def emit(result: Any, as_json: bool, text: str) -> None:
    print(json.dumps(result) if as_json else text)


def oru_describe(status: dict[str, Any]) -> str:
    if status.get("state") == "idle":
        return "no ORU changeout has run"
    head = f"ORU changeout {status['state']}: {100 * status['progress']:.1f} %"
    if status.get("subtask") is not None:
        head += (f", stage {status['stage']} ({status['stage_name']}) subtask {status['subtask']}: "
                 f"{status['title']} [{status['algorithm']}]")
    lines = [head]
    if status.get("holding"):
        lines.append(f"holding {status['holding']}")
    if status.get("failure"):
        lines.append(f"failure: {status['failure']}")
    if status.get("pause"):
        lines.append(f"paused [{status['pause']['code']}]: {status['pause']['message']}")
    for r in status.get("records", []):
        v = r.get("vision")
        if v and r.get("outcome") != "running":
            latency = "-" if v["latency_median"] is None else f"{1e3 * v['latency_median']:.0f} ms"
            lines.append(f"stage {r['stage'] + 1} subtask {r['number']} closed-loop approach {r['outcome']}: "
                         f"{v['detected']}/{v['frames']} frames with the marker, latency {latency}")
    lines += [f"note: {n}" for n in dict.fromkeys(status.get("notes", []))]
    return "\n".join(lines)


ORU_NEEDS_LEASE = {"pause": True, "resume": True, "abort": False}   # abort: like stop, anyone


def oru_simple(verb: str, api: str, token: str | None, as_json: bool) -> None:
    with ApiClient(api, token) as client:
        cmd = f"oru.{verb}"
        result = controlled_call(client, cmd) if ORU_NEEDS_LEASE[verb] else client.call(cmd)
    emit({"state": result}, as_json, f"ORU changeout {result}")


def oru_status(api: str, token: str | None, as_json: bool) -> None:
    with ApiClient(api, token) as client:
        result = client.call("oru.status")
    emit(result, as_json, oru_describe(result))


def control_take(api: str, token: str | None, as_json: bool) -> None:
    with ApiClient(api, token) as client:
        take(client)
        holder = (client.call("status").get("control") or {}).get("holder")
    emit({"control": "taken", "holder": holder}, as_json, f"control held by {holder}")


def control_release(api: str, token: str | None, as_json: bool) -> None:
    with ApiClient(api, token) as client:
        client.call("control.release", lease=lease_store.load(client.address))
    lease_store.forget(api)
    emit({"control": "released"}, as_json, "control released")


def record_start(path: str | None, api: str, token: str | None, as_json: bool) -> None:
    with ApiClient(api, token) as client:
        result = controlled_call(client, "record.start", path=path)
    emit(result, as_json, f"recording to {result['path']}")


def record_stop(api: str, token: str | None, as_json: bool) -> None:
    with ApiClient(api, token) as client:
        result = controlled_call(client, "record.stop")
    emit(result, as_json, f"recording closed: {result['path']} ({result['cycles']} cycles)")


def watch(api: str, token: str | None, rate: float = 5.0, count: int = 0) -> None:
    with ApiClient(api, token) as client:
        status = client.call("status")   # first, then rich's import (~0.1-0.5 s): the daemon hears at once
        from rich.live import Live       # here: the other commands never pay for rich
        from spacearm.console.status_view import status_table
        shown = 0
        with Live(auto_refresh=False) as live:
            try:
                while True:
                    live.update(status_table(status), refresh=True)
                    shown += 1
                    if count and shown >= count:
                        break
                    time.sleep(1.0 / max(rate, 0.1))
                    status = client.call("status")
            except KeyboardInterrupt:
                pass
