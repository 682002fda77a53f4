"""`spacearm approach TARGET [--dz M] [--holding ORU]`: closed-loop approach on the camera.

Moves the end effector to the pre-contact pose above the target store's ORU adapter (or,
holding an ORU, above the slot) under visual feedback, printing the progress and the remaining
error the camera measures. Exit code 0 only when the approach converged; 1 with the reason
(marker lost, too far, error grows, protective stop) otherwise. Needs a daemon started with
--camera (and a simulator with the same --camera).
"""
from __future__ import annotations

import sys
import time

import typer

from spacearm.console.client import ApiClient
from spacearm.console.commands.operate import API_OPTION, JSON_OPTION, TOKEN_OPTION, _controlled_call, _emit
from spacearm.console.errors import CommandFailed, friendly_errors
from spacearm.console.units import UnitError, parse_length


def register(app: typer.Typer) -> None:
    @app.command()
    @friendly_errors
    def approach(target: str = typer.Argument(..., help="store name of the scene file (configs/scene/*.toml)"),
                 dz: str = typer.Option("0.10", "--dz", help="stand-off above the target, m (or 100mm)"),
                 holding: str = typer.Option(None, "--holding", help="name of the ORU the end effector holds"),
                 timeout: float = typer.Option(300.0, "--timeout", help="give up waiting after this many s"),
                 api: str = API_OPTION, token: str = TOKEN_OPTION, as_json: bool = JSON_OPTION) -> None:
        """Closed-loop (visual servo) approach to TARGET's pre-contact pose."""
        try:
            dz_m = parse_length(dz)
        except UnitError as exc:
            raise CommandFailed(str(exc)) from None
        args = {"target": target, "dz": dz_m}
        if holding:
            args["holding"] = holding
        with ApiClient(api, token) as client:
            result = _controlled_call(client, "approach", **args)
            motion = result["motion"]
            deadline = time.monotonic() + timeout
            while True:
                status = client.call("status")
                if status["state"] == "stopped":
                    raise CommandFailed(f"approach failed: {status.get('stop_reason')}")
                if status.get("motions_finished", 0) >= motion:
                    break
                if status["state"] != "enabled":
                    raise CommandFailed(f"approach ended early: arm is {status['state']}")
                if time.monotonic() > deadline:
                    client.call("stop")
                    raise CommandFailed(f"approach did not converge within {timeout:.0f} s; arm stopped")
                if not as_json:
                    print(f"\r  approach {target}: {100 * status.get('progress', 0):5.1f} %", end="", file=sys.stderr)
                time.sleep(0.1)
            if not as_json:
                print(file=sys.stderr)
            _emit({**result, "final": status}, as_json, f"approach to {target} converged (dz {dz_m * 1e3:.0f} mm)")
