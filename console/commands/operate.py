"""Operator commands that talk to a running daemon: status, enable, jog, move, stop, ...

Human-readable output by default, `--json` for scripts. Exit code 0 when the daemon
accepted (and, with --wait, completed) the command; 1 with a one-line reason otherwise.
Units: joint angles in rad unless suffixed (`5deg`), lengths in m unless suffixed (`10mm`).
`move pose` takes the tool pose in the arm's base frame (or relative to the current tool
frame with --frame tool): x y z, then roll pitch yaw about fixed axes, R = Rz(yaw) Ry(pitch) Rx(roll).
"""
from __future__ import annotations

import sys
import time
from typing import Any

import typer

from spacearm.console import daemon_calls
from spacearm.console.control import controlled_call as _controlled_call, take as _take  # noqa: F401 (web, oru)
from spacearm.console.client import DEFAULT_API, ApiClient
from spacearm.console.errors import BadInput, CommandFailed, friendly_errors
from spacearm.console.units import UnitError, parse_angle, parse_length

API_OPTION = typer.Option(DEFAULT_API, "--api", help="Daemon API address (tcp:HOST:PORT or unix:PATH).",
                          envvar="SPACEARM_API")
TOKEN_OPTION = typer.Option(None, "--token", help="API token, when the daemon is exposed.",
                            envvar="SPACEARM_TOKEN")
JSON_OPTION = typer.Option(False, "--json", help="Print the answer as JSON.")
WAIT_OPTION = typer.Option(True, "--wait/--no-wait", help="Wait until the motion has finished.")


_emit = daemon_calls.emit    # (oru.py)


def _wait_for_motion(client: ApiClient, motion: int, as_json: bool) -> dict:
    """Poll status until motion number `motion` has finished; fail on a protective stop."""
    while True:
        status = client.call("status")
        if status["state"] == "stopped":
            raise CommandFailed(f"protective stop: {status.get('stop_reason')}")
        if status.get("motions_finished", 0) >= motion:
            return status
        if status["state"] != "enabled":
            raise CommandFailed(f"motion ended early: arm is {status['state']}")
        if not as_json:
            print(f"\r  {status['mode']}: {100 * status.get('progress', 0):5.1f} %", end="", file=sys.stderr)
        time.sleep(0.1)


def _motion(cmd: str, api: str, token: str | None, as_json: bool, wait: bool, **args: Any) -> None:
    with ApiClient(api, token) as client:
        result = _controlled_call(client, cmd, **args)
        text = f"{result['mode']} started ({result['duration']:.2f} s)"
        if wait:
            status = _wait_for_motion(client, result["motion"], as_json)
            if not as_json:
                print(file=sys.stderr)
            result = {**result, "final": status}
            text = f"{result['mode']} done in {result['duration']:.2f} s"
        _emit(result, as_json, text)


def _angles(values: list[str]) -> list[float]:
    try:
        return [parse_angle(v) for v in values]
    except UnitError as exc:
        raise BadInput(str(exc)) from None


# Let negative numbers through as arguments (click would read "-0.5" as an option).
NUMERIC_ARGS = {"ignore_unknown_options": True}


def register(app: typer.Typer) -> None:
    @app.command()
    @friendly_errors
    def status(api: str = API_OPTION, token: str = TOKEN_OPTION, as_json: bool = JSON_OPTION) -> None:
        """Show the arm's state: mode, joints, forces, cycle statistics, stop reason."""
        from spacearm.console import quick
        quick.run("status", api, token, as_json)

    @app.command()
    @friendly_errors
    def enable(api: str = API_OPTION, token: str = TOKEN_OPTION, as_json: bool = JSON_OPTION,
               wait: bool = typer.Option(True, "--wait/--no-wait", help="Wait until every drive is enabled "
                                         "(fails with the reason and a hint if one does not).")) -> None:
        """Enable all joint drives (brakes released, holding position)."""
        from spacearm.console import quick
        quick.run("enable", api, token, as_json, wait)

    for name, helptext in (("disable", "Hold still, then disable drives and apply brakes."),
                           ("reset", "Clear a protective stop (motion needs enable afterwards).")):
        def make(cmd: str):
            @friendly_errors
            def simple(api: str = API_OPTION, token: str = TOKEN_OPTION, as_json: bool = JSON_OPTION) -> None:
                from spacearm.console import quick
                quick.run(cmd, api, token, as_json)
            simple.__doc__ = helptext
            return simple
        app.command(name)(make(name))

    @app.command()
    @friendly_errors
    def stop(api: str = API_OPTION, token: str = TOKEN_OPTION, as_json: bool = JSON_OPTION) -> None:
        """Protective stop now (any console may stop the arm, control lease or not)."""
        from spacearm.console import quick
        quick.run("stop", api, token, as_json)

    @app.command(context_settings=NUMERIC_ARGS)
    @friendly_errors
    def jog(joint: int = typer.Argument(..., help="Joint number, 1-based."),
            delta: str = typer.Argument(..., help="Angle to move, e.g. 0.05 (rad) or 3deg."),
            speed: float = typer.Option(1.0, help="Fraction of the joint limits, (0, 1]."),
            api: str = API_OPTION, token: str = TOKEN_OPTION, as_json: bool = JSON_OPTION,
            wait: bool = WAIT_OPTION) -> None:
        """Move one joint by DELTA (jerk-limited, within its limits)."""
        if not wait:
            raise BadInput("jog --no-wait: a jog stops when its console disconnects (command "
                                "watchdog); use `move joints --no-wait` for an unattended motion")
        [angle] = _angles([delta])
        _motion("jog", api, token, as_json, wait, joint=joint, delta=angle, speed=speed)

    move_app = typer.Typer(help="Point-to-point moves in joint or Cartesian space.", no_args_is_help=True)

    @move_app.command("joints", context_settings=NUMERIC_ARGS)
    @friendly_errors
    def move_joints(q: list[str] = typer.Argument(..., help="One angle per joint, e.g. 0 90deg -1.2, or a "
                                                  "named posture of the arm file: ready, home, ..."),
                    speed: float = typer.Option(1.0, help="Fraction of the joint limits, (0, 1]."),
                    api: str = API_OPTION, token: str = TOKEN_OPTION, as_json: bool = JSON_OPTION,
                    wait: bool = WAIT_OPTION) -> None:
        """Move all joints to Q or a named posture (Ruckig: jerk-limited, all joints finish together)."""
        if len(q) == 1 and q[0][:1].isalpha():
            _motion("move_joints", api, token, as_json, wait, posture=q[0], speed=speed)
        else:
            _motion("move_joints", api, token, as_json, wait, q=_angles(q), speed=speed)

    @move_app.command("pose", context_settings=NUMERIC_ARGS)
    @friendly_errors
    def move_pose(x: str, y: str, z: str, roll: str, pitch: str, yaw: str,
                  frame: str = typer.Option("base", help="base: absolute pose in the base frame; "
                                            "tool: relative to the current tool frame."),
                  speed: float = typer.Option(1.0, help="Fraction of the Cartesian limits, (0, 1]."),
                  api: str = API_OPTION, token: str = TOKEN_OPTION, as_json: bool = JSON_OPTION,
                  wait: bool = WAIT_OPTION) -> None:
        """Move the tool in a straight line to x y z (m or mm) roll pitch yaw (rad or deg)."""
        try:
            xyz = [parse_length(v) for v in (x, y, z)]
        except UnitError as exc:
            raise BadInput(str(exc)) from None
        _motion("move_pose", api, token, as_json, wait, xyz=xyz, rpy=_angles([roll, pitch, yaw]),
                frame=frame, speed=speed)

    app.add_typer(move_app, name="move")

    control_app = typer.Typer(help="Take or release control of the arm (one console at a time).",
                              no_args_is_help=True)

    @control_app.command("take")
    @friendly_errors
    def control_take(api: str = API_OPTION, token: str = TOKEN_OPTION, as_json: bool = JSON_OPTION) -> None:
        """Take control (or keep it, when this user's consoles hold it); refused while another holds it."""
        daemon_calls.control_take(api, token, as_json)

    @control_app.command("release")
    @friendly_errors
    def control_release(api: str = API_OPTION, token: str = TOKEN_OPTION, as_json: bool = JSON_OPTION) -> None:
        """Release control so another console can take it."""
        daemon_calls.control_release(api, token, as_json)

    app.add_typer(control_app, name="control")

    record_app = typer.Typer(help="Start or stop recording (MCAP + raw CAN trace).", no_args_is_help=True)

    @record_app.command("start")
    @friendly_errors
    def record_start(path: str = typer.Argument(None, help="Output .mcap (default: runs/<time>.mcap)."),
                     api: str = API_OPTION, token: str = TOKEN_OPTION, as_json: bool = JSON_OPTION) -> None:
        """Start recording every cycle."""
        daemon_calls.record_start(path, api, token, as_json)

    @record_app.command("stop")
    @friendly_errors
    def record_stop(api: str = API_OPTION, token: str = TOKEN_OPTION, as_json: bool = JSON_OPTION) -> None:
        """Stop recording and close the file."""
        daemon_calls.record_stop(api, token, as_json)

    app.add_typer(record_app, name="record")

    @app.command()
    @friendly_errors
    def watch(api: str = API_OPTION, token: str = TOKEN_OPTION,
              rate: float = typer.Option(5.0, help="Refreshes per second."),
              count: int = typer.Option(0, help="Stop after this many refreshes (0: until Ctrl-C).")) -> None:
        """Live view of joints, forces and cycle statistics, refreshing in the terminal."""
        daemon_calls.watch(api, token, rate, count)
