"""Controller-side CANopen network of the arm: connection, acyclic services (SDO, NMT), events
and conveniences; its three jobs live in their own modules and are parts of ``ArmNetwork``:

- bring-up (drivers/boot_master.py, per node drivers/bringup.py): boot, reboot handling;
- node health (drivers/health.py): heartbeat/guarding/EMCY consumers, the master's timer;
- cyclic I/O (drivers/cyclic_io.py): SYNC, RPDOs, TPDOs, ``ArmState`` in SI units.

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
Heartbeat loss, EMCYs and node reboots become ``NetworkEvent``s (``poll_events()``), detected
by a monitor thread within ``heartbeat_loss_factor`` (< 3) heartbeat periods.
"""
from __future__ import annotations

import logging
import math
import threading
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import can
import canopen
from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

from spacearm.base.canopen import od
from spacearm.base.canopen.cia402_defs import State
from spacearm.base.canopen.codes import ABORT_NO_OBJECT, ABORT_NO_SUBINDEX
from spacearm.base.canopen.eds import load_od
from spacearm.base.config.bus import DEFAULT_BUS_CONFIG, BusConfig, load_bus_config
from spacearm.base.transport import frame_sender, frames_sender, open_bus
from spacearm.drivers import line_redundancy
from spacearm.drivers.boot_master import BootMaster
from spacearm.drivers.bringup import BringupReport
from spacearm.drivers.cyclic_io import ArmCommand, ArmState, CyclicIO, TpdoRoute
from spacearm.drivers.devices import (DRIVERS, DeviceDriver, EeCommand, EndEffectorDriver, FtDriver,
                                      JointDriver)
from spacearm.drivers.errors import DriverError, NetworkEvent, SdoError, SdoTimeoutError
from spacearm.drivers.health import NodeHealth, HealthMonitor

logger = logging.getLogger(__name__)



@dataclass
class NetworkStats:
    rx_frames: int = 0
    tpdos: int = 0
    expected_tpdos: int = 0   # TPDOs the SYNCs sent so far asked for (live OPERATIONAL nodes)
    syncs_sent: int = 0
    tpdo_timeouts: int = 0
    syncs_kept_off: int = 0   # SYNCs a line fault kept off a redundant pair's active line (nobody could answer)
    unknown: int = 0      # standard frames nobody listens to
    malformed: int = 0    # known service, wrong length
    ignored: int = 0      # error, remote, extended-ID frames
    callback_errors: int = 0
    starved_checks: int = 0     # heartbeat checks made after this process was starved (excess excused)
    starved_time: float = 0.0   # s of starvation excused from heartbeat silence
    guard_toggle_errors: int = 0  # node-guarding answers whose toggle bit did not alternate


class _Listener(can.Listener):
    """Replaces canopen's MessageListener: filters and counts, never raises."""

    needs_rx_line = False     # a redundant pair need not tag frames with their line for it

    def __init__(self, arm: "ArmNetwork"):
        self.arm = arm
        # In-process bus hot path: a standard data frame as plain values, TPDOs decoded in
        # the same call (cyclic_io.py), everything else through the library's subscribers.
        self.on_frame = arm._receive_frame
        self.on_frames = arm._receive_frames     # a burst (a SYNC's TPDOs) in one call

    def on_message_received(self, msg: can.Message) -> None:
        if msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id or getattr(msg, "is_fd", False):
            stats = self.arm.stats
            stats.rx_frames += 1
            stats.ignored += 1
            return
        self.on_frame(msg.arbitration_id, msg.data, msg.timestamp)    # counts it

    def on_error(self, exc: Exception) -> None:
        self.arm.stats.callback_errors += 1

    def stop(self) -> None:
        pass


class ArmNetwork(BootMaster, HealthMonitor, CyclicIO):
    def __init__(self, bus_spec: str, bus_config: BusConfig | str | Path = DEFAULT_BUS_CONFIG):
        self.bus_spec = bus_spec
        self.config = bus_config if isinstance(bus_config, BusConfig) else load_bus_config(bus_config)
        self.config = line_redundancy.bus_config_for(bus_spec, self.config)   # a pair's heartbeat timing
        self.line_redundancy: line_redundancy.LineRedundancyMaster | None = None
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
        self._tpdo_in: dict[int, TpdoRoute] = {}        # COB-ID -> its compiled route (cyclic_io.py)
        self._tpdo_owner: dict[int, str] = {}           # COB-ID -> node name
        self._burst_plans: dict = {}                    # a burst's COB-IDs -> its plan (tpdo_burst.py)
        self.bringup: dict[str, BringupReport] = {}    # what bring-up did per node (status)
        self._tpdo_misses: dict[int, int] = {}          # COB-ID -> SYNCs in a row without it
        self._guarded: dict[int, float] = {}            # node-guarded node ID -> next poll (monotonic)
        self._guard_toggle: dict[int, int] = {}         # node-guarded node ID -> toggle bit of its last answer
        self._slave_locks: dict[str, threading.Lock] = {}  # one boot-slave process per node at a time
        self._following_over: dict[str, int] = {}      # joint -> cycles over its window (master-side check)
        for cfg in self.config.nodes:
            object_dictionary = load_od(cfg.eds_path, cfg.node_id)   # EdsError: bad input, exit 2
            driver = DRIVERS.get(cfg.device, DeviceDriver)(cfg, self.config.bus, object_dictionary)   # generic: raw values
            self.drivers[cfg.name] = driver
            self.health[cfg.name] = NodeHealth(cfg.name, cfg.node_id)
            for spec in driver.tpdos:
                self._tpdo_routes[spec.cob_id] = (driver, spec)
                self._tpdo_in[spec.cob_id] = TpdoRoute(driver, self.health[cfg.name], driver.tpdo_codecs[spec.cob_id])
                self._tpdo_owner[spec.cob_id] = driver.name
            if isinstance(driver, JointDriver):
                self.joints.append(driver)
            elif isinstance(driver, EndEffectorDriver):
                self.end_effector = driver
            elif isinstance(driver, FtDriver):
                self.ft = driver
        # What the cycle walks every SYNC, fixed here with the layouts: the drivers in order,
        # each node's TPDO set (the expected set is their union over the live nodes).
        self._cycle_drivers = [(d, isinstance(d, JointDriver), self.health[d.name]) for d in self.drivers.values()]
        self._tpdo_nodes = [(self.health[d.name], frozenset(s.cob_id for s in d.tpdos)) for d in self.drivers.values()]
        self._owners_of: dict[frozenset[int], frozenset[str]] = {}   # expected TPDOs -> their nodes
        # the cycle takes the lock itself (a C call); the condition on it wakes TPDO waiters
        self._lock = threading.RLock()
        self._cv = threading.Condition(self._lock)
        self._events: deque[NetworkEvent] = deque(maxlen=1000)
        self.event_callbacks: list[Callable[[NetworkEvent], None]] = []
        self._booted: set[int] = set()
        self._received: set[int] = set()
        self._answered: set[str] = set()     # nodes that answered the previous SYNC in its period (cyclic_io.py)
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
        # Lockstep: the SYNC period (s) whose count is controller time; node liveness is then
        # judged per SYNC in controller time (drivers/health.py _lockstep_health). None: wall time.
        self.controller_period: float | None = None
        self._hb_sync = 0
        self._hb_due_now = False
        self._next_own_heartbeat = float("inf")        # wall-clock heartbeat producer (health.py), set by its timer
        self._own_heartbeat_lock = threading.Lock()
        self._lockstep_wait_expired = 0.0     # s of the last TPDO wait that ran out
        self._sync_kept_off = False           # the last SYNC never entered the line (cyclic_io.send_sync)
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
        # RemoteNode follows NMT commands on 0x000 with a parser that raises on short frames
        self.network.unsubscribe(od.NMT_COB_ID)
        self.network.subscribe(od.NMT_COB_ID, self._on_nmt_frame)
        self._connected = True
        self._stop.clear()
        self.line_redundancy = line_redundancy.attach(self)     # None on one line
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
        if self.line_redundancy is not None:
            self.line_redundancy.stop()
        self.network.disconnect()
        self._connected = False

    def __enter__(self):
        return self.connect()

    def __exit__(self, *exc):
        self.close()

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




__all__ = ["ArmNetwork", "ArmState", "ArmCommand", "NodeHealth", "NetworkStats", "EeCommand", "State"]
