"""Controller-side CANopen network of the arm: bring-up, cycle API, monitoring.

    net = ArmNetwork("virtual:arm", "configs/bus/arm.toml")
    net.boot()                 # reset comm, wait boot-ups, configure by SDO, start, verify
    net.enable_all()           # CiA 402 state machines, one transition per cycle
    state = net.cycle(ArmCommand(joint_positions=[...]))   # RPDOs, SYNC, wait TPDOs, read
    net.shutdown()

Free-running (daemon) mode, every SYNC period, never blocking:

    state = net.read()          # values of the last SYNC; state.complete: all TPDOs arrived
    net.write(command)          # state machines one step, RPDOs out
    net.send_sync()
    events = net.poll_events()

Everything in and out is in SI units; no caller sees a COB-ID or an index. ``cycle`` never
sleeps except the optional lockstep wait for this SYNC's TPDOs (bounded by a timeout).
Heartbeat loss and EMCYs become ``NetworkEvent``s (``poll_events()``), detected by a
monitor thread within ``heartbeat_loss_factor`` (< 3) heartbeat periods.
"""
from __future__ import annotations

import logging
import math
import struct
import threading
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import can
import canopen
from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

from spacearm.base.canopen import od
from spacearm.base.runtime.priority import describe, use_fifo
from spacearm.drivers.bringup import BringupReport, NodeBringup
from spacearm.base.config.bus import DEFAULT_BUS_CONFIG, BusConfig, load_bus_config
from spacearm.base.canopen.cia402_defs import State
from spacearm.drivers.devices import (DRIVERS, DeviceDriver, EeCommand, EndEffectorDriver, EndEffectorState, FtDriver,
                             FtState, JointDriver, JointState)
from spacearm.base.canopen.codes import ABORT_NO_OBJECT, ABORT_NO_SUBINDEX
from spacearm.base.canopen.eds import load_od
from spacearm.drivers.errors import BootError, DriverError, NetworkEvent, SdoError, SdoTimeoutError, emcy_text
from spacearm.base.transport import frame_sender, frames_sender, open_bus

logger = logging.getLogger(__name__)


@dataclass
class NodeHealth:
    name: str
    node_id: int
    nmt_state: int | None = None     # last heartbeat state (spacearm.base.canopen.od.NMT_STATE_*)
    alive: bool = False
    last_heartbeat: float | None = None
    emcy_code: int = 0               # last EMCY code (0 after an error reset)

    @property
    def nmt_state_name(self) -> str:
        return od.NMT_STATE_NAMES.get(self.nmt_state, "UNKNOWN")


@dataclass
class ArmState:
    sync: int                        # SYNC number this state belongs to
    complete: bool                   # every expected TPDO of this SYNC arrived
    joints: list[JointState]
    end_effector: EndEffectorState | None
    ft: FtState | None
    nodes: dict[str, NodeHealth]

    @property
    def joint_positions(self) -> list[float]:
        return [j.position for j in self.joints]

    @property
    def all_enabled(self) -> bool:
        return all(j.enabled for j in self.joints)


@dataclass
class ArmCommand:
    joint_positions: Sequence[float | None] | None = None   # rad, CSP targets (None = hold)
    joint_velocities: Sequence[float] | None = None         # rad/s feed-forward
    joint_torques: Sequence[float] | None = None            # N m feed-forward at the joint
    end_effector: EeCommand | None = None


@dataclass
class NetworkStats:
    rx_frames: int = 0
    tpdos: int = 0
    expected_tpdos: int = 0   # TPDOs the SYNCs sent so far asked for (live OPERATIONAL nodes)
    syncs_sent: int = 0
    tpdo_timeouts: int = 0
    unknown: int = 0      # standard frames nobody listens to
    malformed: int = 0    # known service, wrong length
    ignored: int = 0      # error, remote, extended-ID frames
    callback_errors: int = 0
    starved_checks: int = 0     # heartbeat checks made after this process was starved (excess excused)
    starved_time: float = 0.0   # s of starvation excused from heartbeat silence
    guard_toggle_errors: int = 0  # node-guarding answers whose toggle bit did not alternate


class _Listener(can.Listener):
    """Replaces canopen's MessageListener: filters and counts, never raises."""

    def __init__(self, arm: "ArmNetwork"):
        self.arm = arm

    def on_message_received(self, msg: can.Message) -> None:
        stats = self.arm.stats
        stats.rx_frames += 1
        if msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id or getattr(msg, "is_fd", False):
            stats.ignored += 1
            return
        if msg.arbitration_id not in self.arm.network.subscribers:
            stats.unknown += 1
            return
        try:
            self.arm.network.notify(msg.arbitration_id, msg.data, msg.timestamp)
        except Exception:
            stats.callback_errors += 1
            logger.exception("error handling frame %s", msg)

    def on_frame(self, can_id: int, data: bytes, timestamp: float) -> None:
        """In-process bus hot path: a standard data frame as plain values; TPDOs go straight
        to their decoder, everything else through the library's subscribers."""
        arm = self.arm
        arm.stats.rx_frames += 1
        try:
            if can_id in arm._tpdo_routes:
                arm._on_tpdo(can_id, data, timestamp)
            elif can_id in arm.network.subscribers:
                arm.network.notify(can_id, data, timestamp)
            else:
                arm.stats.unknown += 1
        except Exception:
            arm.stats.callback_errors += 1
            logger.exception("error handling frame 0x%03X", can_id)

    def on_error(self, exc: Exception) -> None:
        self.arm.stats.callback_errors += 1

    def stop(self) -> None:
        pass


class ArmNetwork:
    def __init__(self, bus_spec: str, bus_config: BusConfig | str | Path = DEFAULT_BUS_CONFIG):
        self.bus_spec = bus_spec
        self.config = bus_config if isinstance(bus_config, BusConfig) else load_bus_config(bus_config)
        self.network = canopen.Network()
        self.network.NOTIFIER_CYCLE = 0.05    # receive-thread wake-up; bounds close() time
        self.network.listeners = [_Listener(self)]
        self.stats = NetworkStats()
        self.drivers: dict[str, DeviceDriver] = {}
        self.remote: dict[str, canopen.RemoteNode] = {}
        self.health: dict[str, NodeHealth] = {}
        self.joints: list[JointDriver] = []
        self.end_effector: EndEffectorDriver | None = None
        self.ft: FtDriver | None = None
        self._tpdo_routes: dict[int, tuple[DeviceDriver, object]] = {}
        self.bringup: dict[str, BringupReport] = {}    # what bring-up did per node (status)
        self._tpdo_misses: dict[int, int] = {}          # COB-ID -> SYNCs in a row without it
        self._tpdo_lengths: dict[int, int] = {}         # id(PdoSpec) -> its length (the mapping is fixed)
        self._guarded: dict[int, float] = {}            # node-guarded node ID -> next poll (monotonic)
        self._guard_toggle: dict[int, int] = {}         # node-guarded node ID -> toggle bit of its last answer
        for cfg in self.config.nodes:
            object_dictionary = load_od(cfg.eds_path, cfg.node_id)   # EdsError: bad input, exit 2
            driver = DRIVERS[cfg.device](cfg, self.config.bus, object_dictionary)
            self.drivers[cfg.name] = driver
            self.health[cfg.name] = NodeHealth(cfg.name, cfg.node_id)
            for spec in driver.tpdos:
                self._tpdo_routes[spec.cob_id] = (driver, spec)
            if isinstance(driver, JointDriver):
                self.joints.append(driver)
            elif isinstance(driver, EndEffectorDriver):
                self.end_effector = driver
            elif isinstance(driver, FtDriver):
                self.ft = driver
        self._cv = threading.Condition()
        self._events: deque[NetworkEvent] = deque(maxlen=1000)
        self.event_callbacks: list[Callable[[NetworkEvent], None]] = []
        self._booted: set[int] = set()
        self._received: set[int] = set()
        # TPDOs this SYNC should bring, fixed at the SYNC; None after a heartbeat/NMT change
        # (then every TPDO wakes the waiter, which recomputes). Waking the cycle only when the
        # set is complete saves a thread hop per TPDO.
        self._expected: set[int] | None = None
        self._monitoring = False
        # SCHED_FIFO priority of the timer thread alone (0: inherit): a lockstep daemon's cycle
        # runs at normal priority, yet its heartbeat must not stall behind other load
        self.timer_priority = 0
        self.timer_scheduling = "inherited"
        self._sync = 0
        self._connected = False
        self._stop = threading.Event()
        self._monitor: threading.Thread | None = None
        self._excused: dict[str, float] = {}          # node -> starvation excused from its current silence
        self._excused_since: dict[str, float] = {}    # node -> last_heartbeat after the last excuse

    # ------------------------------------------------------------------ connection
    def connect(self) -> "ArmNetwork":
        if self._connected:
            return self
        self.network.bus = open_bus(self.bus_spec, hub_reports=True)   # the master hears the hub's lateness
        self.network.connect()
        self._send_frame = frame_sender(self.network.bus)
        self._send_frames = frames_sender(self.network.bus)
        if hasattr(self.network.bus, "add_inline_listener"):
            # in-process bus: TPDOs are handled in the simulator's sending thread (see
            # drivers/transport); the library's Notifier stays for the queued fallback
            for listener in self.network.listeners:
                self.network.bus.add_inline_listener(listener)
        for name, driver in self.drivers.items():
            node = canopen.RemoteNode(driver.node_id, driver.od)
            node.sdo.RESPONSE_TIMEOUT = self.config.bus.sdo_timeout
            self.network.add_node(node)
            # our own heartbeat/EMCY consumers replace the library's (they tolerate bad frames)
            self.network.unsubscribe(od.HEARTBEAT_BASE + driver.node_id)
            self.network.unsubscribe(od.EMCY_BASE + driver.node_id)
            self.network.subscribe(od.HEARTBEAT_BASE + driver.node_id, self._make_hb_handler(name))
            self.network.subscribe(od.EMCY_BASE + driver.node_id, self._make_emcy_handler(name))
            self.remote[name] = node
        for cob in self._tpdo_routes:
            self.network.subscribe(cob, self._on_tpdo)
        # RemoteNode follows NMT commands on 0x000 with a parser that raises on short frames
        self.network.unsubscribe(od.NMT_COB_ID)
        self.network.subscribe(od.NMT_COB_ID, self._on_nmt_frame)
        self._connected = True
        self._stop.clear()
        self._monitor = threading.Thread(target=self._monitor_loop, name="arm-heartbeat-monitor", daemon=True)
        self._monitor.start()
        return self

    def close(self) -> None:
        """Disconnect without touching the nodes."""
        if not self._connected:
            return
        self._stop.set()
        if self._monitor is not None:
            self._monitor.join(1.0)
        self.network.disconnect()
        self._connected = False

    def __enter__(self):
        return self.connect()

    def __exit__(self, *exc):
        self.close()

    # ------------------------------------------------------------------ bring-up
    def boot(self, timeout: float | None = None) -> None:
        """Reset communication of all nodes, wait for their boot-ups, configure each by SDO
        (heartbeat, SYNC, scaling, limits, PDO mapping), start them and verify they report
        OPERATIONAL. Raises BootError naming the node(s) at fault."""
        self.connect()
        timeout = self.config.bus.boot_timeout if timeout is None else timeout
        self._monitoring = False
        with self._cv:
            self._booted.clear()
            for h in self.health.values():
                h.alive, h.nmt_state, h.last_heartbeat = False, None, None
        self._nmt(od.NMT_RESET_COMMUNICATION)
        expected = {d.node_id for d in self.drivers.values()}
        deadline = time.monotonic() + timeout
        with self._cv:
            self._cv.wait_for(lambda: expected <= self._booted, timeout=max(0.0, deadline - time.monotonic()))
            missing = [d for d in self.drivers.values() if d.node_id not in self._booted]
        if missing:
            raise BootError(f"boot failed: no boot-up message within {timeout:.1f} s from "
                            + ", ".join(d.label for d in missing))
        for driver in self.drivers.values():
            self._configure(driver)
        now = time.monotonic()
        with self._cv:
            for h in self.health.values():
                h.last_heartbeat, h.alive = now, True
        self._monitoring = True
        self._nmt(od.NMT_START)
        wait = 3.0 * max(n.heartbeat_period for n in self.config.nodes) + 0.2
        with self._cv:
            self._cv.wait_for(lambda: all(h.nmt_state == od.NMT_STATE_OPERATIONAL for h in self.health.values()),
                              timeout=wait)
            not_op = [self.drivers[n] for n, h in self.health.items() if h.nmt_state != od.NMT_STATE_OPERATIONAL]
        if not_op:
            raise BootError("boot failed: not OPERATIONAL after NMT start: " + ", ".join(
                f"{d.label} reports {self.health[d.name].nmt_state_name}" for d in not_op))

    def recover(self, node: str | int, timeout: float = 1.0) -> None:
        """Bring one node back after a reboot (``bootup`` event): configure it by SDO again
        and start it. Its CiA 402 axis restarts from SWITCH ON DISABLED (goal kept)."""
        driver = self._driver(node)
        self._configure(driver)
        with self._cv:
            h = self.health[driver.name]
            h.last_heartbeat, h.alive = time.monotonic(), True
        self._nmt(od.NMT_START, driver.node_id)
        with self._cv:
            ok = self._cv.wait_for(lambda: self.health[driver.name].nmt_state == od.NMT_STATE_OPERATIONAL,
                                   timeout=timeout)
        if not ok:
            raise BootError(f"{driver.label} not OPERATIONAL after recovery "
                            f"(reports {self.health[driver.name].nmt_state_name})")

    def _configure(self, driver: DeviceDriver) -> None:
        """Configure one node from its EDS and configuration (drivers/bringup.py)."""
        report = self.bringup[driver.name] = NodeBringup(self, driver, self.config.bus).run()
        if report.node_guarding:       # polled by the monitor thread; answers arrive as heartbeats
            self._guarded[driver.node_id] = 0.0

    # ------------------------------------------------------------------ SDO (acyclic)
    def _driver(self, node: str | int) -> DeviceDriver:
        for d in self.drivers.values():
            if d.name == node or d.node_id == node:
                return d
        raise KeyError(f"no node {node!r} in the bus config")

    def _var(self, driver: DeviceDriver, index: int, sub: int):
        obj = driver.od[index]
        return obj[sub] if hasattr(obj, "subindices") else obj

    def sdo_read(self, node: str | int, index: int, subindex: int = 0):
        """Read one object (decoded with the EDS type). Raises SdoError / SdoTimeoutError."""
        d = self._driver(node)
        try:
            data = self.remote[d.name].sdo.upload(index, subindex)
        except SdoAbortedError as exc:
            raise SdoError(d.label, "read", index, subindex, exc.code) from None
        except SdoCommunicationError as exc:
            raise SdoTimeoutError(f"{d.label}: SDO read 0x{index:04X}:{subindex:02X}: {exc}") from None
        except Exception as exc:   # a malformed response frame
            raise DriverError(f"{d.label}: SDO read 0x{index:04X}:{subindex:02X}: bad response: {exc}") from None
        try:
            return self._var(d, index, subindex).decode_raw(data)
        except KeyError:
            return data

    def sdo_write(self, node: str | int, index: int, subindex: int, value) -> None:
        """Write one object (encoded with the EDS type; bytes are sent as is)."""
        d = self._driver(node)
        if isinstance(value, (bytes, bytearray)):
            data = bytes(value)
        else:
            try:
                data = self._var(d, index, subindex).encode_raw(value)
            except KeyError:
                raise SdoError(d.label, "write", index, subindex, ABORT_NO_OBJECT if index not in d.od
                               else ABORT_NO_SUBINDEX) from None
        try:
            self.remote[d.name].sdo.download(index, subindex, data)
        except SdoAbortedError as exc:
            raise SdoError(d.label, "write", index, subindex, exc.code) from None
        except SdoCommunicationError as exc:
            raise SdoTimeoutError(f"{d.label}: SDO write 0x{index:04X}:{subindex:02X}: {exc}") from None
        except Exception as exc:   # a malformed response frame
            raise DriverError(f"{d.label}: SDO write 0x{index:04X}:{subindex:02X}: bad response: {exc}") from None

    def tare_ft(self) -> None:
        """Zero the force/torque sensor at its current load (takes effect at the next SYNC)."""
        if self.ft is None:
            raise DriverError("no ft_sensor on this bus")
        self.sdo_write(self.ft.name, od.FT_TARE, 0, 1)

    # ------------------------------------------------------------------ NMT
    def _nmt(self, command: int, node_id: int = 0) -> None:
        self.network.send_message(od.NMT_COB_ID, bytes([command, node_id]))

    def nmt_stop(self, node: str | int | None = None) -> None:
        self._nmt(od.NMT_STOP, 0 if node is None else self._driver(node).node_id)

    def nmt_start(self, node: str | int | None = None) -> None:
        self._nmt(od.NMT_START, 0 if node is None else self._driver(node).node_id)

    # ------------------------------------------------------------------ cycle API
    def send_sync(self) -> int:
        """Send one SYNC; returns its number. TPDOs arriving from now on belong to it."""
        with self._cv:
            if self._expected is not None and self._monitoring:
                self._count_missing_tpdos(self._expected_tpdos() - self._received)
            self._sync += 1
            self._received = set()
            self._expected = self._expected_tpdos()
            self.stats.expected_tpdos += len(self._expected)
        self._send(od.SYNC_COB_ID_DEFAULT, b"")
        self.stats.syncs_sent += 1
        return self._sync

    def _count_missing_tpdos(self, missing: set[int]) -> None:
        """A mapped TPDO of a live node missing for tpdo_loss_cycles SYNCs in a row is a
        fault event naming the node and the PDO (once per loss; re-armed when it returns)."""
        limit = self.config.bus.tpdo_loss_cycles
        for cob in list(self._tpdo_misses):
            if cob not in missing:
                del self._tpdo_misses[cob]
        for cob in missing:
            n = self._tpdo_misses[cob] = self._tpdo_misses.get(cob, 0) + 1
            if n == limit:
                driver, spec = self._tpdo_routes[cob]
                self._event("tpdo_missing", driver, f"{driver.label}: {spec.label} missing for {n} SYNCs "
                                                    f"(mapped, node alive)")

    def _expected_tpdos(self) -> set[int]:
        cobs = set()
        for d in self.drivers.values():
            h = self.health[d.name]
            if h.alive and h.nmt_state == od.NMT_STATE_OPERATIONAL:
                cobs.update(s.cob_id for s in d.tpdos)
        return cobs

    def wait_all_tpdos(self, timeout: float | None = None) -> bool:
        """Lockstep: wait until every live OPERATIONAL node sent this SYNC's TPDOs."""
        timeout = self.config.bus.lockstep_timeout if timeout is None else timeout
        with self._cv:
            ok = self._cv.wait_for(lambda: self._expected_tpdos() <= self._received, timeout=timeout)
        if not ok:
            self.stats.tpdo_timeouts += 1
        return ok

    def write(self, command: ArmCommand | None = None) -> None:
        """Apply a command (SI units), advance the drivers' state machines one step from the
        latest TPDOs and send the RPDOs. Call before send_sync()."""
        if not self._connected:
            raise DriverError("the network is not connected: call boot() first")
        if command is not None:
            self._apply(command)
        frames = []
        with self._cv:
            for d in self.drivers.values():
                d.step()
                if isinstance(d, JointDriver):
                    if d.axis.fault_reset_failed:
                        d.axis.fault_reset_failed = False
                        self._event("fault_reset_failed", d,
                                    f"{d.label}: fault reset did not clear the fault "
                                    f"(error 0x{d.value(od.ERROR_CODE):04X} {emcy_text(d.value(od.ERROR_CODE))})",
                                    d.value(od.ERROR_CODE))
                    if d.axis.fault_cleared:
                        self._event("fault_cleared", d, f"{d.label}: fault cleared")
                h = self.health[d.name]
                # Also to a node whose heartbeat was lost: it may still listen (only its
                # heartbeat producer failed), and the protective stop must reach it.
                if h.nmt_state == od.NMT_STATE_OPERATIONAL:
                    frames += d.rpdo_frames()
        if frames:
            if not self._connected:
                raise DriverError("the network is not connected: call boot() first")
            with self.network.send_lock:
                self._send_frames(frames)      # one write on the loopback bus

    def _send(self, can_id: int, data: bytes) -> None:
        """The cycle's frames (SYNC, RPDOs): plain values to the bus, no Message on the
        in-process bus; the library's send lock keeps them whole against SDO/NMT senders."""
        if not self._connected:
            raise DriverError("the network is not connected: call boot() first")
        with self.network.send_lock:
            self._send_frame(can_id, data)

    def _apply(self, c: ArmCommand) -> None:
        for i, j in enumerate(self.joints):
            if c.joint_positions is not None and i < len(c.joint_positions) and c.joint_positions[i] is not None:
                j.target = float(c.joint_positions[i])
            if c.joint_velocities is not None and i < len(c.joint_velocities):
                j.velocity_ff = float(c.joint_velocities[i])
            if c.joint_torques is not None and i < len(c.joint_torques):
                j.torque_ff = float(c.joint_torques[i])
        if c.end_effector is not None and self.end_effector is not None:
            self.end_effector.command(c.end_effector)

    def nodes_missing_tpdos(self) -> list[str]:
        """Names of live nodes whose TPDOs of the current SYNC have not all arrived."""
        with self._cv:
            missing = self._expected_tpdos() - self._received
            return sorted({self._tpdo_routes[cob][0].name for cob in missing})

    def tpdos_complete(self) -> bool:
        """Have all expected TPDOs of the last SYNC arrived (non-blocking)?"""
        with self._cv:
            return self._expected_tpdos() <= self._received

    def read(self, complete: bool | None = None) -> ArmState:
        """The latest values in SI units (non-blocking). ``complete`` defaults to
        tpdos_complete(): whether they all belong to the last SYNC."""
        with self._cv:
            if complete is None:
                complete = self._expected_tpdos() <= self._received
            return ArmState(
                sync=self._sync, complete=complete,
                joints=[j.state() for j in self.joints],
                end_effector=self.end_effector.state() if self.end_effector else None,
                ft=self.ft.state() if self.ft else None,
                nodes={n: NodeHealth(**vars(h)) for n, h in self.health.items()})

    def cycle(self, command: ArmCommand | None = None, wait: bool = True,
              timeout: float | None = None) -> ArmState:
        """One control cycle: write(command), send_sync(), [wait_all_tpdos()], read()."""
        self.write(command)
        self.send_sync()
        if wait:
            self.wait_all_tpdos(timeout)
        return self.read()

    # ------------------------------------------------------------------ conveniences
    def run_until(self, predicate: Callable[[ArmState], bool], max_cycles: int = 100,
                  command: ArmCommand | None = None) -> ArmState:
        """Lockstep cycles (with the same command) until predicate(state); DriverError if not."""
        state = self.read()
        for _ in range(max_cycles):
            state = self.cycle(command)
            if predicate(state):
                return state
        raise DriverError(f"condition not reached within {max_cycles} cycles")

    def move_to(self, positions: Sequence[float | None], duration: float, settle_cycles: int = 5) -> ArmState:
        """Lockstep CSP move of the joints to ``positions`` (rad, None = stay) along a cosine
        blend lasting ``duration`` s, then ``settle_cycles`` more cycles. A demo helper: the
        daemon streams its own (Ruckig) trajectory through cycle()/write()."""
        start = self.read().joint_positions
        goal = [s if p is None else float(p) for s, p in zip(start, list(positions) + [None] * len(start))]
        n = max(1, round(duration / self.config.bus.sync_period))
        state = self.read()
        for k in range(1, n + 1 + settle_cycles):
            blend = (1.0 - math.cos(math.pi * min(k, n) / n)) / 2.0
            state = self.cycle(ArmCommand(joint_positions=[a + (b - a) * blend for a, b in zip(start, goal)]))
        return state

    def enable_all(self, max_cycles: int = 50) -> ArmState:
        """Enable every joint through the CiA 402 state machine (a few cycles)."""
        for j in self.joints:
            j.axis.enable()
        state = self.read()
        for _ in range(max_cycles):
            state = self.cycle()
            if state.all_enabled:
                return state
        raise DriverError("not enabled after %d cycles: %s" % (max_cycles, ", ".join(
            f"{j.name} in {j.state.value}" for j in state.joints if not j.enabled)))

    def disable_all(self) -> None:
        for j in self.joints:
            j.axis.disable()

    def quick_stop(self, joint: int | str | None = None) -> None:
        for j in self._select(joint):
            j.axis.quick_stop()

    def fault_reset(self, joint: int | str | None = None) -> None:
        for j in self._select(joint):
            j.axis.fault_reset()

    def _select(self, joint) -> list[JointDriver]:
        if joint is None:
            return list(self.joints)
        if isinstance(joint, int):
            return [self.joints[joint]]
        return [j for j in self.joints if j.name == joint]

    def set_mode(self, joint: int | str | None, mode: int) -> None:
        """Operating mode of joints: od.MODE_CSP (default) or od.MODE_PROFILE_POSITION. In
        profile position, ArmCommand.joint_positions are set-points the drive profiles to
        (profile velocity/acceleration from the bus config); JointState.target_reached."""
        for j in self._select(joint):
            j.set_mode(mode)
            if not any(e.index == od.MODES_OF_OPERATION for spec in j.rpdos for e in spec.entries):
                self.sdo_write(j.name, od.MODES_OF_OPERATION, 0, mode)   # not in its RPDOs (compact drive)

    def shutdown(self, cycles: int = 5) -> None:
        """Disable all joints (brakes engage), put the nodes in PRE-OPERATIONAL, disconnect."""
        if self._connected:
            self.disable_all()
            for _ in range(cycles):
                self.cycle(timeout=0.1)
            self._monitoring = False
            self._nmt(od.NMT_PRE_OPERATIONAL)
        self.close()

    # ------------------------------------------------------------------ events
    def poll_events(self) -> list[NetworkEvent]:
        """Drain the events (heartbeat loss, EMCY, ...) since the last call. Non-blocking."""
        out = []
        while self._events:
            out.append(self._events.popleft())
        return out

    def _event(self, kind: str, driver: DeviceDriver, message: str, code: int = 0) -> None:
        event = NetworkEvent(kind, driver.name, driver.node_id, message, code)
        self._events.append(event)
        for cb in self.event_callbacks:
            try:
                cb(event)
            except Exception:
                logger.exception("event callback failed")

    # ------------------------------------------------------------------ receive handlers
    def _make_hb_handler(self, name: str):
        driver = self.drivers[name]

        def on_heartbeat(can_id, data, timestamp):
            if len(data) != 1:
                self.stats.malformed += 1
                return
            state = data[0] & 0x7F
            if driver.node_id in self._guarded:
                self._check_guard_toggle(driver, data[0], state)
            with self._cv:
                h = self.health[name]
                previous, was_alive = h.nmt_state, h.alive
                h.last_heartbeat = time.monotonic()
                h.nmt_state = state
                h.alive = True
                if state == od.NMT_STATE_BOOTUP:
                    self._booted.add(driver.node_id)
                    driver.values.clear()       # whatever it reported before is gone
                    if self._monitoring:
                        self._event("bootup", driver, f"{driver.label} rebooted (boot-up message)")
                elif self._monitoring and previous == od.NMT_STATE_OPERATIONAL and state != previous:
                    self._event("nmt_state", driver, f"{driver.label} left OPERATIONAL: now {h.nmt_state_name}",
                                state)
                if self._monitoring and not was_alive:
                    self._event("heartbeat_restored", driver, f"{driver.label} heartbeat back")
                if state != previous or not was_alive:
                    self._expected = None
                self._cv.notify_all()
        return on_heartbeat

    def _check_guard_toggle(self, driver: DeviceDriver, answer: int, state: int) -> None:
        """CiA 301 node guarding: each answer's bit 7 alternates, starting from 0 after boot-up.
        An answer with the same bit as the one before means an answer was lost or repeated
        (a stale frame, a second node on the ID): counted and reported, not a node loss."""
        toggle = answer & 0x80
        if state == od.NMT_STATE_BOOTUP:
            self._guard_toggle.pop(driver.node_id, None)
            return
        last = self._guard_toggle.get(driver.node_id)
        self._guard_toggle[driver.node_id] = toggle
        if last is not None and toggle == last:
            self.stats.guard_toggle_errors += 1
            if self._monitoring:
                self._event("guard_toggle", driver, f"{driver.label}: node-guarding answer did not toggle "
                                                    "(an answer was lost or repeated)")

    def _make_emcy_handler(self, name: str):
        driver = self.drivers[name]

        def on_emcy(can_id, data, timestamp):
            if len(data) != 8:
                self.stats.malformed += 1
                return
            code, register, _ = struct.unpack("<HB5s", bytes(data))
            self.health[name].emcy_code = code
            if code & 0xFF00 == 0:
                self._event("emcy_reset", driver, f"{driver.label}: error reset", code)
            else:
                self._event("emcy", driver, f"{driver.label}: EMCY 0x{code:04X} {emcy_text(code)} "
                                            f"(error register 0x{register:02X})", code)
        return on_emcy

    def _on_nmt_frame(self, can_id, data, timestamp):
        if len(data) != 2:
            self.stats.malformed += 1

    def _on_tpdo(self, can_id, data, timestamp):
        driver, spec = self._tpdo_routes[can_id]
        length = self._tpdo_lengths.get(id(spec))
        if length is None:
            length = self._tpdo_lengths[id(spec)] = spec.length
        if len(data) < length:
            self.stats.malformed += 1
            return
        with self._cv:
            driver.decode(spec, bytes(data))
            self._received.add(can_id)
            self.stats.tpdos += 1
            if self._expected is None or self._expected <= self._received:
                self._cv.notify_all()

    def _poll_guarded(self, now: float) -> None:
        """Node guarding: an RTR on 700h + ID every heartbeat period of each guarded node."""
        for node_id, due in list(self._guarded.items()):
            if now >= due:
                self._guarded[node_id] = max(due + self._driver(node_id).cfg.heartbeat_period, now)
                try:
                    self.network.send_message(od.HEARTBEAT_BASE + node_id, b"\x00", remote=True)
                except Exception as exc:
                    logger.warning("node guarding request to node %d not sent: %s", node_id, exc)

    def _monitor_loop(self) -> None:
        """The master's timer: its own heartbeat, node-guarding polls and heartbeat-loss checks.

        Starvation vs device loss: silence is counted only while this process could observe
        the bus. When the loop wakes more than STARVED_SLACK after it meant to (the host or a
        busy process held the CPU; frames may be waiting unread in a queue), the excess is
        not counted as any node's silence: every last-heard time moves forward by it, and a
        loss that the wall clock alone would have declared becomes a `late_cycle` event
        (informational) instead of `heartbeat_lost`. A node that really went silent is still
        declared lost after heartbeat_loss_factor (< 3) periods of observed silence; the time
        excused per silence is capped at the margin up to 3 periods, so the bound of 3
        heartbeat periods holds whatever the load."""
        if self.timer_priority:
            self.timer_scheduling = use_fifo(self.timer_priority) or describe()
        factor = self.config.bus.heartbeat_loss_factor
        period = self.config.bus.master_heartbeat_period
        hb_cob = od.HEARTBEAT_BASE + self.config.bus.master_node_id
        next_hb = time.monotonic()
        due = next_hb
        while not self._stop.wait(max(MONITOR_MIN_SLEEP, due - time.monotonic())):
            now = time.monotonic()
            excess = now - due - STARVED_SLACK
            due = now + MONITOR_PERIOD
            if period > 0 and now >= next_hb:          # the controller's own heartbeat producer
                next_hb = max(next_hb + period, now)
                try:
                    self.network.send_message(hb_cob, bytes([od.NMT_STATE_OPERATIONAL]))
                except Exception as exc:
                    logger.warning("controller heartbeat not sent: %s", exc)
            if period > 0:
                due = min(due, next_hb)
            if not self._monitoring:
                continue
            self._poll_guarded(now)
            with self._cv:
                if excess > 0:
                    # Starved: excuse the time, and judge only at the next pass, once the
                    # receive path has had the CPU to deliver what waited meanwhile.
                    self.stats.starved_time += excess
                    self._excuse(now, excess, factor)
                    due = now + RECHECK_AFTER_STARVED
                    continue
                for cfg in self.config.nodes:
                    h = self.health[cfg.name]
                    if h.alive and h.last_heartbeat is not None and now - h.last_heartbeat > factor * cfg.heartbeat_period:
                        h.alive = False
                        d = self.drivers[cfg.name]
                        self._event("heartbeat_lost", d,
                                    f"{d.label}: heartbeat lost (silent for {now - h.last_heartbeat:.3f} s, "
                                    f"period {cfg.heartbeat_period:.3f} s)")
                        self._expected = None
                        self._cv.notify_all()

    def _excuse(self, now: float, excess: float, factor: float) -> None:
        """This process was starved for `excess` s: that time is not silence (see _monitor_loop)."""
        judged = []
        for cfg in self.config.nodes:
            h = self.health[cfg.name]
            if not h.alive or h.last_heartbeat is None:
                continue
            # at most the margin between the loss factor and 3 periods per silence (less one
            # monitor pass): a real loss is still declared within 3 heartbeat periods
            cap = max(0.0, (3.0 - factor) * cfg.heartbeat_period - MONITOR_PERIOD)
            if h.last_heartbeat != self._excused_since.get(cfg.name):
                self._excused[cfg.name] = 0.0
            grant = min(excess, cap - self._excused.get(cfg.name, 0.0))
            if grant <= 0.0:
                continue
            if now - h.last_heartbeat > factor * cfg.heartbeat_period:
                judged.append(cfg.name)
            h.last_heartbeat += grant
            self._excused[cfg.name] = self._excused.get(cfg.name, 0.0) + grant
            self._excused_since[cfg.name] = h.last_heartbeat
        self.stats.starved_checks += 1
        if judged:
            names = ", ".join(judged)
            event = NetworkEvent("late_cycle", judged[0], self.drivers[judged[0]].node_id,
                                 f"late cycle: the controller was starved for {excess:.3f} s; heartbeat "
                                 f"silence of {names} in that window not counted as node loss")
            self._events.append(event)


# The master's timer (heartbeat producer, guarding, loss checks) runs at least every
# MONITOR_PERIOD; a wake later than STARVED_SLACK past its due time counts as starvation.
MONITOR_PERIOD = 0.010      # s
MONITOR_MIN_SLEEP = 0.0005  # s
STARVED_SLACK = 0.020       # s
RECHECK_AFTER_STARVED = 0.003  # s: a starved pass judges nothing; the next one comes this soon


__all__ = ["ArmNetwork", "ArmState", "ArmCommand", "NodeHealth", "NetworkStats", "EeCommand", "State"]
