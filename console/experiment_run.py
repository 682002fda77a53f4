"""`diagnose --run`: the designed experiment executed on a running daemon, which records it.

The moves go through the daemon's own lease-checked `move_joints` (its planner enforces the
arm's limits, its supervision stops the arm on any fault), so the experiment is no more
privileged than an operator at the console: it takes control only if nobody holds it, and
refuses with one line when the daemon is unreachable, the lease is someone else's, the arm
is not enabled or is another arm. The daemon writes the recording to a path this console
names, and this console reads it from there: the API listens on the loopback interface, so
both run on one machine. The moves send their planned velocity as the drives' velocity offset
(60B1h) and the recording keeps only the targets: the re-diagnosis replays the offset, read
from the recording (offline/diagnosis/command_timing.py).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from spacearm.console.arm_session import DaemonArm
from spacearm.console.client import ApiClient
from spacearm.console.control import controlled_call, take
from spacearm.console.errors import CommandFailed
from spacearm.controller.daemon.api_errors import ErrorCode
from spacearm.offline.diagnosis.experiment import DWELL, JointLimit, experiment_moves


def take_control(api: str, token: str | None) -> None:
    """Before a long diagnosis: the daemon answers and this console holds (or now takes) control,
    so `--run` refuses at once rather than after the analysis."""
    with ApiClient(api, token) as client:
        take(client)


def run_experiment(joints: list[int], limits: list[JointLimit], arm_name: str, n_joints: int, out: Path,
                   api: str, token: str | None) -> Path:
    """Run the experiment for the 0-based `joints` from where the daemon's arm stands, record
    it to `out` (.mcap) and return the recording's path. The daemon's own recording, if it
    had one, goes on afterwards in a new file of its record directory."""
    with ApiClient(api, token) as client:
        arm = DaemonArm(client, settle=0.0)
        status = arm.status()
        _check_daemon(status, arm_name, n_joints)
        start = np.array([j["q_cmd"] for j in status["joints"]])
        moves = experiment_moves(joints, start, limits)
        was_recording = status.get("recording") is not None
        out.parent.mkdir(parents=True, exist_ok=True)   # the daemon refuses a missing directory
        controlled_call(client, "record.start", path=str(out.resolve()))
        try:
            for move in moves:
                arm.hold(move.dwell)
                arm.move_to(move.target, speed=move.speed)
            arm.hold(DWELL)
        finally:
            stopped = controlled_call(client, "record.stop")
            if was_recording:
                controlled_call(client, "record.start")
    return Path(stopped["path"])


def _check_daemon(status: dict, arm_name: str, n_joints: int) -> None:
    """Only the arm the experiment was designed for, enabled, moves."""
    if status.get("arm") != arm_name:
        raise CommandFailed(f"the daemon runs arm {status.get('arm')!r}, the experiment was designed for "
                            f"{arm_name!r} (--arm): not run", ErrorCode.BAD_ARGUMENT)
    if len(status.get("joints", [])) != n_joints:
        raise CommandFailed(f"the daemon's arm has {len(status.get('joints', []))} joints, the recording "
                            f"{n_joints}: not run", ErrorCode.BAD_ARGUMENT)
    if status.get("state") != "enabled":
        raise CommandFailed(f"the arm is {status.get('state')}: enable it (`spacearm enable`) before "
                            "`diagnose --run`", ErrorCode.NOT_ENABLED)
