"""A daemon-driven arm for routines that move and measure (calibration): move, settle, read.

Moves go through the same validated, lease-checked commands as `spacearm move joints`; the
routine waits for its own motion number, then a settling time counted in control cycles, so
it behaves the same in real time and in lockstep.
"""
from __future__ import annotations

import time

import numpy as np

from spacearm.console.client import ApiClient
from spacearm.console.commands.operate import _controlled_call, _wait_for_motion
from spacearm.console.errors import CommandFailed


class DaemonArm:
    def __init__(self, client: ApiClient, speed: float = 1.0, settle: float = 0.5):
        self.client = client
        self.speed = speed
        self.settle = settle

    def status(self) -> dict:
        return self.client.call("status")

    def q(self, status: dict | None = None) -> np.ndarray:
        status = status or self.status()
        return np.array([j["q"] for j in status["joints"]])

    def enable(self, timeout: float = 10.0) -> None:
        status = self.status()
        if status["state"] == "stopped":
            raise CommandFailed(f"protective stop active ({status.get('stop_reason')}); reset first")
        if status["state"] != "enabled":
            _controlled_call(self.client, "enable")
        deadline = time.monotonic() + timeout
        while self.status()["state"] != "enabled":
            if time.monotonic() > deadline:
                raise CommandFailed(f"arm not enabled within {timeout:.0f} s")
            time.sleep(0.02)

    def move_to(self, q: np.ndarray, speed: float | None = None) -> np.ndarray:
        """Jerk-limited joint move to q (at `speed`, a fraction of the joint limits; default the
        arm's), then settle; returns the measured joint angles."""
        started = _controlled_call(self.client, "move_joints", q=[float(v) for v in q],
                                   speed=self.speed if speed is None else speed)
        status = _wait_for_motion(self.client, started["motion"], as_json=True)
        return self.q(self.hold(self.settle, status))

    def hold(self, seconds: float, status: dict | None = None) -> dict:
        """Wait while the arm stands still for `seconds` of control cycles (the same in real
        time and in lockstep); fails if the arm leaves the enabled state meanwhile."""
        status = status or self.status()
        until = status["cycle"] + int(np.ceil(seconds / status["period"]))
        while status["cycle"] < until:
            time.sleep(min(0.02, max(seconds, 1e-3) / 10))
            status = self.status()
            if status["state"] != "enabled":
                raise CommandFailed(f"arm {status['state']} while settling: {status.get('stop_reason')}")
        return status
