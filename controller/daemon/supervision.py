"""Safety supervision, checked every cycle before any command is written.

Each check looks at this cycle's measurement (and the command sent last cycle) and names
what is wrong. The daemon reacts to the first finding with a protective stop and keeps
the finding as the stop reason until an explicit reset.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controller.daemon.state import Measurement


@dataclass(frozen=True)
class SupervisionLimits:
    q_min: np.ndarray
    q_max: np.ndarray
    v_max: np.ndarray
    position_margin: float = 0.0087      # rad (0.5 deg) beyond a soft limit before stopping
    velocity_tolerance: float = 0.2      # fraction above v_max before stopping
    following_error: float = 0.0175      # rad (1 deg) between last target and measurement
    wrench_force_limit: float = 150.0    # N
    wrench_torque_limit: float = 30.0    # N m
    missing_pdo_cycles: int = 5          # consecutive cycles without a node's PDOs (100 ms at 50 Hz,
                                         # below the 250 ms heartbeat-loss detection)


@dataclass(frozen=True)
class Finding:
    code: str      # short machine-readable reason, e.g. "position_limit"
    message: str   # what a person needs to know, with joint names and values

    def __str__(self) -> str:
        return self.message


class Supervisor:
    def __init__(self, limits: SupervisionLimits, joint_names: list[str]):
        self.limits = limits
        self.names = joint_names
        self._missing_count: dict[str, int] = {}

    def check(self, m: Measurement, last_target: np.ndarray | None, moving: bool) -> list[Finding]:
        lim = self.limits
        findings: list[Finding] = []
        for event in m.events:
            if event.kind in ("heartbeat_lost", "emcy", "fault", "bootup"):
                label = {"heartbeat_lost": "heartbeat lost", "emcy": "emergency message",
                         "fault": "drive fault", "bootup": "unexpected boot-up (node restarted)"}
                detail = f": {event.detail}" if event.detail else ""
                findings.append(Finding(event.kind, f"{event.node}: {label[event.kind]}{detail}"))
        for node in list(self._missing_count):
            if node not in m.missing:
                del self._missing_count[node]
        for node in m.missing:
            self._missing_count[node] = self._missing_count.get(node, 0) + 1
            if self._missing_count[node] >= lim.missing_pdo_cycles:
                findings.append(Finding("pdo_missing", f"{node}: no process data for "
                                        f"{self._missing_count[node]} cycles"))
        for i in np.flatnonzero(m.joints_faulted):
            findings.append(Finding("fault", f"{self.names[i]}: drive in fault"))
        low = m.q < lim.q_min - lim.position_margin
        high = m.q > lim.q_max + lim.position_margin
        for i in np.flatnonzero(low | high):
            bound = lim.q_min[i] if low[i] else lim.q_max[i]
            findings.append(Finding("position_limit", f"{self.names[i]}: position {m.q[i]:.4f} rad "
                                    f"beyond limit {bound:.4f} rad"))
        for i in np.flatnonzero(np.abs(m.dq) > lim.v_max * (1.0 + lim.velocity_tolerance)):
            findings.append(Finding("velocity_limit", f"{self.names[i]}: velocity {m.dq[i]:.4f} rad/s "
                                    f"above limit {lim.v_max[i]:.4f} rad/s"))
        if moving and last_target is not None:
            error = np.abs(last_target - m.q)
            for i in np.flatnonzero(error > lim.following_error):
                findings.append(Finding("following_error", f"{self.names[i]}: following error "
                                        f"{error[i]:.4f} rad above {lim.following_error:.4f} rad"))
        force = float(np.linalg.norm(m.wrench[:3]))
        torque = float(np.linalg.norm(m.wrench[3:]))
        if m.wrench_overload:
            findings.append(Finding("ft_overload", "force/torque sensor: overload flag set"))
        elif force > lim.wrench_force_limit or torque > lim.wrench_torque_limit:
            findings.append(Finding("ft_limit", f"force/torque {force:.1f} N / {torque:.2f} N m above "
                                    f"limits {lim.wrench_force_limit:.0f} N / {lim.wrench_torque_limit:.0f} N m"))
        return findings
