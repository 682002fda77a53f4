"""Safety supervision, checked every cycle before any command is written.

Each check looks at this cycle's measurement (and the command sent last cycle) and names
what is wrong. The daemon reacts to the first finding with a protective stop and keeps
the finding as the stop reason until an explicit reset.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from spacearm.base.config.limits import SupervisionConfig
from spacearm.controller.cycle import Finding, FindingCode, Measurement


@dataclass(frozen=True)
class SupervisionLimits:
    """The arm's joint limits and its supervision settings (the arm file's [supervision] table);
    the settings read as attributes of the limits (`limits.ft_jump_force`)."""
    q_min: np.ndarray
    q_max: np.ndarray
    v_max: np.ndarray
    # rad between last target and measurement, per joint from the arm file's [joints.drive]
    following_error: float | np.ndarray = 0.0175
    settings: SupervisionConfig = SupervisionConfig()

    def __getattr__(self, name: str):
        return getattr(self.settings, name)


# Late cycles not counted against one gap in a node's process data: with missing_pdo_cycles = 5
# a real loss stops within 8 cycles, inside the fault tests' bound of 12.
LATE_CYCLES_EXCUSED = 3
# Cycles of one gap not counted while the host holds the vCPU the nodes' process runs on
# (Measurement.host_stalled): the ~100 ms stalls seen at a VM's CPU quota twice over. A node
# lost during such a stall still stops, at most this much later.
HOST_CYCLES_EXCUSED = 10

EVENT_LABELS = {FindingCode.HEARTBEAT_LOST: "heartbeat lost", FindingCode.EMCY: "emergency message",
                FindingCode.FAULT: "drive fault", FindingCode.BOOTUP: "unexpected boot-up (node restarted)",
                FindingCode.BUS_LINES_LOST: "both bus lines lost"}


class Supervisor:
    def __init__(self, limits: SupervisionLimits, joint_names: list[str]):
        self.limits = limits
        self.names = joint_names
        self._missing_count: dict[str, int] = {}
        self._excused: dict[str, int] = {}     # node -> late cycles not counted in its current gap
        self._host_excused: dict[str, int] = {}   # node -> host-stall cycles not counted in its gap
        self.late_cycles_excused = 0
        self.host_cycles_excused = 0
        self._last_wrench: np.ndarray | None = None
        self._wrench_changes = 0
        self._wrench_same = 0
        self._ft_live = False     # seen changing every cycle (noise): the frozen check is armed
        self._bounds: _Bounds | None = None

    def _bounds_of(self, limits: SupervisionLimits) -> "_Bounds":
        """The limits as every cycle compares them, worked out once per limits object."""
        if self._bounds is None or self._bounds.limits is not limits:
            self._bounds = _Bounds(limits)
        return self._bounds

    def check(self, m: Measurement, last_target: np.ndarray | None, moving: bool) -> list[Finding]:
        lim = self.limits
        bounds = self._bounds_of(lim)
        findings: list[Finding] = []
        for event in m.events:
            label = EVENT_LABELS.get(event.kind)
            if label is not None:
                detail = f": {event.detail}" if event.detail else ""
                findings.append(Finding(event.kind, f"{event.node}: {label}{detail}", node=event.node))
        for node in {*self._missing_count, *self._excused, *self._host_excused}:
            # a node whose last missing data came after all, before this SYNC, answered: the gap
            # ended there (it, the bus or this process was slow; a silent node never answers),
            # also a gap whose every cycle was excused
            if node not in m.missing or node in m.answered_late:
                self._missing_count.pop(node, None)
                self._excused.pop(node, None)
                self._host_excused.pop(node, None)
        counted = []
        for node in m.missing if not m.bridged else ():   # a line switch under way (bounded)
            if m.late and self._excused.get(node, 0) < LATE_CYCLES_EXCUSED:
                # The cycle itself ran late (this process was starved): the data may be sitting
                # unread, so the cycle is no evidence of a lost node; the count is held, not
                # reset, and only a few times per gap, so a real loss still stops.
                self._excused[node] = self._excused.get(node, 0) + 1
                self.late_cycles_excused += 1
                continue
            if m.host_stalled and self._host_excused.get(node, 0) < HOST_CYCLES_EXCUSED:
                # the host held the vCPU of the node's process: silence of its host, not of the
                # node; held like a late cycle, for longer (the stall outlasts a late wake)
                self._host_excused[node] = self._host_excused.get(node, 0) + 1
                self.host_cycles_excused += 1
                continue
            self._missing_count[node] = self._missing_count.get(node, 0) + 1
            counted.append(node)
        silent = [n for n in counted if self._missing_count[n] >= bounds.missing_pdo_cycles]
        for node in silent:
            # every node silent at once points at the bus or the devices' host, one at that node:
            # the stop's message (the first finding's) names the others
            others = [n for n in silent if n != node]
            findings.append(Finding(FindingCode.PDO_MISSING, f"{node}: no process data for "
                                    f"{self._missing_count[node]} cycles"
                                    + (f" ({', '.join(others)} silent too)" if others else ""), node=node))
        # each array test first as one count of true elements (np.count_nonzero: ~0.2 us against
        # ndarray.any()'s ~0.9 us on these few joints, issue 35; nonzero either way, NaN included):
        # the indices are looked up only for a finding
        if np.count_nonzero(m.joints_faulted):
            for i in np.flatnonzero(m.joints_faulted):
                findings.append(Finding(FindingCode.FAULT, f"{self.names[i]}: drive in fault", joint=self.names[i]))
        if bounds.outside(m.q, m.dq):     # numpy and the indices only where a joint is beyond one
            findings.extend(self._limit_findings(m, lim, bounds))
        if moving and last_target is not None and not m.bridged:    # bridged: the positions are stale
            error = np.abs(last_target - m.q)
            behind = error > lim.following_error
            if np.count_nonzero(behind):
                window = np.broadcast_to(lim.following_error, error.shape)
                for i in np.flatnonzero(behind):
                    findings.append(Finding(FindingCode.FOLLOWING_ERROR, f"{self.names[i]}: following error "
                                            f"{error[i]:.4f} rad above {window[i]:.4f} rad", joint=self.names[i]))
        force, torque = _norms(m.wrench)
        if m.wrench_overload:
            findings.append(Finding(FindingCode.FT_OVERLOAD, "force/torque sensor: overload flag set"))
        elif force > bounds.wrench_force_limit or torque > bounds.wrench_torque_limit:
            findings.append(Finding(FindingCode.FT_LIMIT, f"force/torque {force:.1f} N / {torque:.2f} N m above "
                                    f"limits {bounds.wrench_force_limit:.0f} N / {bounds.wrench_torque_limit:.0f} N m"))
        findings.extend(self._check_ft_signal(m, bounds))
        return findings

    def _limit_findings(self, m: Measurement, lim: SupervisionLimits, bounds: "_Bounds") -> list[Finding]:
        """The position and velocity findings, joint by joint."""
        findings = []
        low = m.q < bounds.q_low
        high = m.q > bounds.q_high
        if np.count_nonzero(low) or np.count_nonzero(high):
            for i in np.flatnonzero(low | high):
                bound = lim.q_min[i] if low[i] else lim.q_max[i]
                findings.append(Finding(FindingCode.POSITION_LIMIT, f"{self.names[i]}: position {m.q[i]:.4f} rad "
                                        f"beyond limit {bound:.4f} rad", joint=self.names[i]))
        fast = np.abs(m.dq) > bounds.v_high
        if np.count_nonzero(fast):
            for i in np.flatnonzero(fast):
                findings.append(Finding(FindingCode.VELOCITY_LIMIT, f"{self.names[i]}: velocity {m.dq[i]:.4f} "
                                        f"rad/s above limit {lim.v_max[i]:.4f} rad/s", joint=self.names[i]))
        return findings

    def _check_ft_signal(self, m: Measurement, lim: "_Bounds") -> list[Finding]:
        """Jump and frozen checks on the F/T reading. A cycle with any node's data missing
        repeats the last received values: it is no evidence either way, so the frozen count is
        held (a reset there let a loaded machine's occasional late TPDO postpone the stop)."""
        last, self._last_wrench = self._last_wrench, m.wrench.copy()
        if last is None:
            self._wrench_same = 0
            return []
        if m.missing:
            return []
        findings = []
        step = m.wrench - last
        df, dt = _norms(step)
        if df > lim.ft_jump_force or dt > lim.ft_jump_torque:
            findings.append(Finding(FindingCode.FT_JUMP, f"force/torque sensor: reading jumped by {df:.1f} N / "
                                    f"{dt:.2f} N m in one cycle (limits {lim.ft_jump_force:.0f} N / "
                                    f"{lim.ft_jump_torque:.0f} N m)"))
        if not np.count_nonzero(step):   # every component exactly 0 (a NaN counts as a change, as in array_equal)
            self._wrench_same += 1
            if not self._ft_live:
                self._wrench_changes = 0
        else:
            self._wrench_same = 0
            self._wrench_changes += 1
            self._ft_live = self._ft_live or self._wrench_changes >= lim.ft_live_changes
        if lim.ft_frozen_cycles > 0 and self._ft_live and self._wrench_same >= lim.ft_frozen_cycles:
            findings.append(Finding(FindingCode.FT_FROZEN, f"force/torque sensor: reading frozen (identical for "
                                    f"{self._wrench_same} cycles)"))
        return findings


class _Bounds:
    """A SupervisionLimits' thresholds as the cycle compares them (the settings' attributes
    read once, not through SupervisionLimits.__getattr__ every cycle)."""

    def __init__(self, limits: SupervisionLimits):
        self.limits = limits
        self.q_low = limits.q_min - limits.position_margin
        self.q_high = limits.q_max + limits.position_margin
        self.v_high = limits.v_max * (1.0 + limits.velocity_tolerance)
        for name in ("missing_pdo_cycles", "wrench_force_limit", "wrench_torque_limit", "ft_jump_force",
                     "ft_jump_torque", "ft_live_changes", "ft_frozen_cycles"):
            setattr(self, name, getattr(limits, name))
        # the same thresholds as Python floats, for outside(); None where they are no plain
        # vector of joints (numpy's broadcasting then decides, every cycle)
        vectors = (self.q_low, self.q_high, self.v_high)
        plain = all(type(v) is np.ndarray and v.ndim == 1 and v.dtype is _F64 and len(v) == len(self.q_low)
                    for v in vectors)
        self._plain = tuple(zip(*(v.tolist() for v in vectors))) if plain else None

    def outside(self, q, dq) -> bool:
        """Is a joint beyond its position or velocity bound (True also where that takes numpy
        to tell)? The comparisons of the findings' arrays as Python floats, joint by joint: the
        same float64 values and the same answers (NaN beyond nothing), without the four numpy
        calls a cycle on a handful of joints (issue 35)."""
        plain = self._plain
        if (plain is None or type(q) is not np.ndarray or type(dq) is not np.ndarray or q.dtype is not _F64
                or dq.dtype is not _F64 or q.shape != dq.shape or q.shape != (len(plain),)):
            return True
        for x, v, (low, high, top) in zip(q.tolist(), dq.tolist(), plain):
            if x < low or x > high or abs(v) > top:
                return True
        return False


_F64 = np.dtype(float)


def _norms(wrench) -> tuple[float, float]:
    """np.linalg.norm of a wrench's force and of its torque without its Python-level dispatch:
    the same square root of the same dot product (numpy computes it so for a 1-D float array),
    so the same floats; the wrench converted once for both."""
    w = np.asarray(wrench, dtype=float)
    force, torque = w[:3], w[3:]
    return math.sqrt(force.dot(force)), math.sqrt(torque.dot(torque))
