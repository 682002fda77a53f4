"""The daemon's hardware interface: CANopen network in, plain measurements out, and back.

Like a ros2_control hardware interface, it is the only part of the daemon that knows
about the drivers: `read()` sends this cycle's SYNC and collects its TPDOs (waiting for
every node in lockstep, or up to a small budget in real time), `write()` turns the
controller's command into drive state-machine requests and RPDOs.
"""
from __future__ import annotations

import time as time_module
from dataclasses import replace
from typing import Sequence

import numpy as np

from spacearm.base.canopen.cia402_defs import State
from spacearm.base.canopen.codes import TPDO_BASE
from spacearm.base.canopen.od import EeCommand
from spacearm.base.config.arm import DriveLimits
from spacearm.base.config.bus import BusConfig, JointSettings
from spacearm.base.runtime.host_cpus import HostStallWatch
from spacearm.controller.cycle import Command, DeviceEvent, EndEffectorState, FindingCode, Measurement, built
from spacearm.controller.daemon.stops import DriveRequest
from spacearm.drivers.network import ArmCommand, ArmNetwork, ArmState
from spacearm.drivers.peer_timing import PeerTimingListener

# The drives' own position limits (607Dh) sit this far outside the arm file's limits, beyond
# the controller's supervision margin, so the controller always stops first and the drive
# limit is the independent backstop.
DRIVE_LIMIT_MARGIN = 0.05  # rad

# A cycle whose I/O ran this many periods late (read after the last one, or TPDO wait past its
# budget) was starved: its missing process data is reported as `late_cycle`, not counted as loss.
LATE_CYCLE_SLACK = 0.5

POWERED = (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE, State.FAULT_REACTION_ACTIVE)
# JointState.enabled and .fault as the cycle tests them, without a property call per joint
_ENABLED, _FAULTS = State.OPERATION_ENABLED, (State.FAULT, State.FAULT_REACTION_ACTIVE)

# 605Ah: quick-stop ramp (6085h), then switch on disabled: the drive's own stop is category 1
QUICK_STOP_OPTION = 2

# Network event kinds the supervisor treats as faults (others are informational).
FAULT_EVENTS = {"heartbeat_lost": FindingCode.HEARTBEAT_LOST, "bootup": FindingCode.BOOTUP, "emcy": FindingCode.EMCY,
                "fault_reset_failed": FindingCode.FAULT, "bus_lines_lost": FindingCode.BUS_LINES_LOST}
# Network event kinds recorded with their code (drivers/line_redundancy.py), never a stop.
RECORDED_EVENTS = {"line_switch": FindingCode.LINE_SWITCH, "line_switch_complete": FindingCode.LINE_SWITCH_COMPLETE}


def with_drive_limits(bus: BusConfig, q_min, q_max, drives: Sequence[DriveLimits] = (),
                      deceleration: Sequence[float] = ()) -> BusConfig:
    """The bus configuration with each joint drive's limits taken from the arm file: 607Dh
    position limits (outside the arm's, see DRIVE_LIMIT_MARGIN) and, where the arm file gives
    its drives ([joints.drive]), 607Fh maximum velocity, 6072h maximum torque and, where stated,
    6065h following-error window, so the drives (simulated or real) enforce the arm's own
    limits, not a test bed's. `deceleration` (the arm file's acceleration limits) becomes each
    drive's quick-stop ramp 6085h with 605Ah = 2 (ramp, then power off and brake): a stop the
    drive makes on its own (node lost, fault, the master gone) keeps the arm's deceleration
    limit, as the controller's own stop does (controller/daemon/stops.py). Bring-up writes them
    where the drive's EDS has the objects."""
    nodes, joint = [], 0
    for node in bus.nodes:
        if node.device == "joint_drive":
            settings = node.joint or JointSettings()
            limits: dict = {"lower": float(q_min[joint]) - DRIVE_LIMIT_MARGIN,
                            "upper": float(q_max[joint]) + DRIVE_LIMIT_MARGIN}
            if joint < len(drives):
                drive = drives[joint]
                limits["max_velocity"] = min(float(drive.velocity), 10.0)           # 607Fh field range
                limits["profile_velocity"] = min(settings.profile_velocity, limits["max_velocity"])
                limits["max_torque"] = min(float(drive.torque) / settings.rated_joint_torque, 3.0)
                if "following_error" in drive.model_fields_set:
                    # only where the arm file states it: the test bed's drives keep their 6065h
                    limits["following_error_window"] = float(drive.following_error)
            if joint < len(deceleration):
                limits["quick_stop_deceleration"] = float(deceleration[joint])
                limits["quick_stop_option"] = QUICK_STOP_OPTION
            node = node.model_copy(update={"joint": settings.model_copy(update=limits)})
            joint += 1
        nodes.append(node)
    return bus.model_copy(update={"nodes": nodes})


_EE_STATES: dict = {}    # the driver's EeState -> the cycle's EndEffectorState (a handful)


def _end_effector_state(ee) -> EndEffectorState:
    """EndEffectorState(ee.state.name.lower()), looked up once per state (the enum's name and
    call cost ~1 us a cycle, issue 35); NONE without an end effector."""
    if ee is None:
        return EndEffectorState.NONE
    state = _EE_STATES.get(ee.state)
    if state is None:
        state = _EE_STATES[ee.state] = EndEffectorState(ee.state.name.lower())
    return state


class CanopenHardware:
    """The one owner of the CAN network in the daemon (boot, SYNC, PDOs, fault reset, statistics)."""

    def __init__(self, bus: str, bus_config: BusConfig, lockstep: bool, realtime_budget: float = 0.005):
        self.network = ArmNetwork(bus, bus_config)
        # the simulator's and hub's own lateness (not on a COB-ID a device's PDOs use)
        self.peers = PeerTimingListener(self.network.network, device_cob_ids={
            base + node.node_id for node in bus_config.nodes for base in TPDO_BASE})
        self.lockstep = lockstep
        if lockstep:
            self.network.controller_period = self.network.config.bus.sync_period
        self.realtime_budget = realtime_budget
        self._goal = "disabled"     # enabled | quick_stop | disable | disabled: the drives' last request
        self.info_events: list[str] = []
        self.last_io_wait = 0.0    # s the last read() waited for its SYNC's TPDOs
        self.period = self.network.config.bus.sync_period
        self._last_read: float | None = None
        self.late_cycles = 0       # cycles whose missing data was excused as the controller's own lateness
        self.late_answers = 0      # nodes' answers that came after the TPDO wait, within their period
        self.host_stalled_cycles = 0   # cycles whose missing data came while the host held a vCPU
        self.host_watch = HostStallWatch()   # tests give it their own /proc/stat
        self._missing_at_read: tuple[str, ...] = ()   # nodes missing at the last read

    @property
    def dof(self) -> int:
        return len(self.network.joints)

    @property
    def joint_names(self) -> list[str]:
        return [j.name for j in self.network.joints]

    @property
    def node_count(self) -> int:
        return len(self.network.drivers)

    @property
    def boot_timeout(self) -> float:
        return self.network.config.bus.boot_timeout

    def start(self, boot_timeout: float | None = None) -> None:
        self.network.boot(boot_timeout)

    def fault_reset(self) -> None:
        self.network.fault_reset()

    def statistics(self) -> dict:
        lines = self.network.line_redundancy
        return {**vars(self.network.stats), "late_cycles": self.late_cycles, "late_answers": self.late_answers,
                "host_stalled_cycles": self.host_stalled_cycles,
                **({"bus_lines": lines.status()} if lines is not None else {})}

    def bringup_report(self) -> dict:
        """Per node: SDO writes at bring-up, optional objects its EDS lacks, how it is guarded."""
        return {name: vars(report) for name, report in getattr(self.network, "bringup", {}).items()}

    def read(self, time: float) -> Measurement:
        started = time_module.monotonic()
        sync = self.network.send_sync()
        timeout = None if self.lockstep else self.realtime_budget
        complete = self.network.wait_all_tpdos(timeout)
        done = time_module.monotonic()
        self.last_io_wait = done - started
        late = 0.0
        host_stalled = False
        if not self.lockstep:
            # /proc/stat costs ~0.2 ms to read: only while data is missing (the watch's baseline
            # is the gap's first cycle) and once after it, when a held vCPU counts its steal
            if not complete or self.host_watch.watching:
                host_stalled = self.host_watch.sample(done)
            if complete:
                self.host_watch.reset()
            # How late this cycle's I/O ran: a read more than a period after the last one, or
            # a TPDO wait that overshot its budget, means this process did not get the CPU.
            if self._last_read is not None:
                late = started - self._last_read - self.period
            late = max(late, self.last_io_wait - self.realtime_budget)
        self._last_read = started
        # of the nodes missing at the last read, those whose data came before this SYNC went out
        answered_late = tuple(self.network.answered_last_sync(self._missing_at_read)) if self._missing_at_read else ()
        self.late_answers += len(answered_late)
        # the nodes' health only where _measurement looks at it: a cycle with data missing
        state = self.network.read(complete, nodes=not complete, joints=False)
        events = []
        for event in self.network.poll_events():
            kind = FAULT_EVENTS.get(event.kind) or RECORDED_EVENTS.get(event.kind)
            if kind is None:
                self.info_events.append(str(event))
            else:
                events.append(DeviceEvent(event.node, kind, event.message))
        starved = late > LATE_CYCLE_SLACK * self.period
        measurement = self._measurement(time, sync, state, tuple(events), late if starved else 0.0,
                                        host_stalled)
        self._missing_at_read = measurement.missing
        if answered_late:
            measurement = replace(measurement, answered_late=answered_late)
        redundancy = self.network.line_redundancy
        if measurement.missing and redundancy is not None and redundancy.bridging():
            redundancy.bridged_cycles += 1      # the missing data is the line switch's (bounded)
            measurement = replace(measurement, bridged=True)
        return measurement

    def _measurement(self, time: float, sync: int, state: ArmState,
                     events: tuple[DeviceEvent, ...], late: float = 0.0,
                     host_stalled: bool = False) -> Measurement:
        readings = state.readings
        if readings is None:        # an ArmState of JointStates (read() by default)
            readings = [(j.position, j.velocity, j.torque, j.state) for j in state.joints]
        # one column per field (zip), not a pass over the joints' states per field (issue 35)
        q, dq, tau, states = zip(*readings) if readings else ((), (), (), ())
        missing: tuple[str, ...] = ()
        if not state.complete:
            dead = [name for name, health in state.nodes.items() if not health.alive]
            missing = tuple(dead + self.network.nodes_missing_tpdos())
            if late > 0.0:
                self.late_cycles += 1
                events += (DeviceEvent(missing[0] if missing else "", FindingCode.LATE_CYCLE,
                                       f"late cycle: I/O {1e3 * late:.1f} ms late; missing process data of "
                                       f"{', '.join(missing)} not counted as node loss"),)
            elif host_stalled:
                self.host_stalled_cycles += 1
                events += (DeviceEvent(missing[0] if missing else "", FindingCode.HOST_STALL,
                                       f"host stall: {self.host_watch.held}; missing process data of "
                                       f"{', '.join(missing)} counted only after the stall"),)
        ft = state.ft
        wrench = np.zeros(6) if ft is None else np.array([*ft.force, *ft.torque], dtype=float)
        return built(Measurement, {
            "time": time, "sync_counter": sync,
            "q": np.array(q),
            "dq": np.array(dq),
            "tau": np.array(tau),
            "joints_enabled": np.array([s == _ENABLED for s in states]),
            "joints_faulted": np.array([s in _FAULTS for s in states]),
            "wrench": wrench, "wrench_overload": bool(ft.overload) if ft else False,
            "end_effector": _end_effector_state(state.end_effector),
            "events": events, "missing": missing, "late": late > 0.0 and bool(missing), "bridged": False,
            "host_stalled": host_stalled and late <= 0.0, "answered_late": (),
            "joints_powered": np.array([s in POWERED for s in states])})

    def write(self, command: Command, stop: DriveRequest | None = None) -> None:
        """`stop`: what a protective stop asks of drives the command no longer enables (None:
        not stopped, plain disable). A change of request is passed on even after the drives
        left operation, so a quick stop escalated to power off reaches them."""
        goal = "enabled" if command.enable else (stop.value if stop is not None else "disabled")
        if goal != self._goal:
            if command.enable:
                for joint in self.network.joints:
                    joint.axis.enable()
            elif stop is DriveRequest.QUICK_STOP:
                self.network.quick_stop()
            elif self._goal != "disabled":
                self.network.disable_all()
        self._goal = goal
        q, dq = command.q, command.dq
        # Python floats straight from the arrays (tolist), not a numpy scalar per joint that
        # _apply converts again: the same values (issue 35)
        self.network.write(ArmCommand(joint_positions=q.tolist() if type(q) is np.ndarray else list(q),
                                      joint_velocities=(dq.tolist() if type(dq) is np.ndarray else list(dq))
                                      if len(dq) else None,
                                      end_effector=(EeCommand[command.end_effector.name] if command.end_effector
                                                    else None)))

    def stop(self) -> None:
        self.network.shutdown()
