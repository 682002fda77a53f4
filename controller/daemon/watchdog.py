"""Command watchdog: a jog lives only while the console that started it is alive.

Policy (README, "Safety behaviour"): a jog is the operator's hand on the arm, like a teach
pendant's dead-man switch. The console that starts it must keep its connection open and be
heard from (any request; a waiting console polls status every 0.1 s) at least every
`JOG_KEEPALIVE` seconds, or the cycle makes a protective stop. Planned moves (`move joints`,
`move pose`) are bounded, validated end to end before they start, and may be started with
`--no-wait` by scripts: they run to their end without a keep-alive (any console may `stop`).
Commands from inside the daemon (the demo's scripted checkout, session None) have no
watchdog: if that script dies, the daemon dies with it.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable

from spacearm.controller.cycle import Finding, FindingCode, Measurement
from spacearm.controller.modes import PlannedMode
from spacearm.controller.planning.joint_move import JointSetpoint

JOG_KEEPALIVE = 1.0  # s without a request from the jogging console before a protective stop


@dataclass
class KeepAliveMode(PlannedMode):
    """A planned mode that fails (protective stop) once its console went silent or away."""
    session: Any = None          # command_api.Session of the console that started it
    timeout: float = JOG_KEEPALIVE
    now: Callable[[], float] = time.monotonic

    def _next_setpoint(self, t: float, m: Measurement | None = None) -> JointSetpoint:
        self._failure = self._silence()
        return super()._next_setpoint(t, m)

    def _silence(self) -> Finding | None:
        s = self.session
        if s is None:
            return None
        if s.closed.is_set():
            return Finding(FindingCode.COMMAND_WATCHDOG, f"{self.name}: the console that started it disconnected "
                           f"({s.peer}, session {s.id})")
        silent = self.now() - s.last_seen
        if silent > self.timeout:
            return Finding(FindingCode.COMMAND_WATCHDOG, f"{self.name}: no keep-alive from its console for "
                           f"{silent:.1f} s (limit {self.timeout:.1f} s)")
        return None
