"""Hosts every simulated node of a bus config on one bus connection.

One process, one bus handle, many independent nodes: each has its own node ID, object
dictionary, NMT state, SDO server and heartbeat. A single receive thread (python-can
Notifier) routes frames to the nodes; a timer thread produces heartbeats. The shared
plant advances exactly one SYNC period per received SYNC.

    sim = start_simulator("virtual:arm", "configs/bus/arm.toml")
    ...
    sim.stop()
"""
from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import can
from canopen.sdo import SdoAbortedError

from spacearm.base.canopen import od, peer_timing
from spacearm.base.config.bus import DEFAULT_BUS_CONFIG, BusConfig, check_axis_kinds, load_bus_config
from spacearm.base.transport import frame_sender, frames_sender, open_bus
from spacearm.firmware_sim import line_selection, simcore
from spacearm.firmware_sim.end_effector import EndEffectorNode
from spacearm.firmware_sim.ft_sensor import FtSensorNode
from spacearm.firmware_sim.joint_drive import JointDriveNode
from spacearm.firmware_sim.node import SimNode
from spacearm.firmware_sim.plant import Plant, PlantConfig, load_plant_config

logger = logging.getLogger(__name__)


_HEARTBEAT_KEY = (od.PRODUCER_HEARTBEAT, 0)      # param()'s cache key of 1017h


def _consumers_quiet(node: SimNode, consumed: dict, now: float) -> bool:
    """True when node.check_consumers(now) would do nothing: its consumer entries are cached
    and current, and every consumed heartbeat is known and within its timeout. Asked for
    every node at every SYNC on the SYNC time base, where nothing times out nearly always
    (issue 35: a call, a copy of the dict and a loop per node and SYNC)."""
    cached = node._consumer_entries
    if cached is None or cached[2] != node._params.epoch:
        return False
    entries = cached[0]
    for producer, last in consumed.items():
        timeout = entries.get(producer)
        if timeout is None or now - last > timeout:
            return False
    return True


def _never_rpdo(cid: int) -> bool:
    """COB-IDs _rebuild_routes never routes to an RPDO (NMT, SDO requests, heartbeats): a frame
    of these needs no fresh routes."""
    return cid == od.NMT_COB_ID or od.SDO_RX_BASE < cid <= od.SDO_RX_BASE + 127 \
        or od.HEARTBEAT_BASE < cid <= od.HEARTBEAT_BASE + 127


def _direct_route(node: SimNode) -> tuple | None:
    """The compiled core's route to the node's RPDOs (_simcore.c rpdo_burst, its R_* order): the
    node, its PDO engine, its write rules as its only write callback, SimNode.on_rpdo (the core
    checks per frame that it is the node's: no line gate, no subclass's own), and what a node
    sets once in __init__ (its write callbacks list, data store, param() cache, statistics,
    fault switches, its lock's acquire and release), so the core stores an RPDO as
    PdoEngine.on_rpdo does without looking them up per frame; then its on_write function if a
    pure check (SimNode.pure_write_check) and the node's memo of the chunks that passed it, which
    lives as long as the node (a pure check's answer never changes); None while the node has
    other write callbacks."""
    callbacks = node.local._write_callbacks
    if len(callbacks) != 1 or callbacks[0] != node._on_od_write:
        return None
    accepted = node.__dict__.setdefault("_accepted_writes", {})
    return (node, node.pdo_engine, callbacks[0], SimNode.on_rpdo, callbacks, node.local.data_store, node._params,
            node.stats, node.faults, node._lock.acquire, node._lock.release, node.pure_write_check(), accepted)


def _tpdo_route(node: SimNode, send_many) -> tuple:
    """The compiled core's route to the node's SYNC TPDOs (_simcore.c tpdo_burst, its T_* order):
    the node, its PDO engine, its LocalNode, its lock's acquire and release, SimNode.send_tpdos
    (the core checks per SYNC that it is the node's: no line gate, no subclass's own) and the
    simulator's send_many as the node holds it (the core checks it still does)."""
    return node, node.pdo_engine, node.local, node._lock.acquire, node._lock.release, SimNode.send_tpdos, send_many


@dataclass
class SimStats:
    rx_frames: int = 0
    syncs: int = 0
    unknown: int = 0      # standard frames of no service any node listens to
    malformed: int = 0    # NMT/SYNC frames with a wrong length
    ignored: int = 0      # error, remote, extended-ID and FD frames
    internal_errors: int = 0
    starved_time: float = 0.0   # s the timer scheduler woke late beyond STARVED_SLACK (not counted as silence)
    held_time: float = 0.0      # s a timer pass lasted beyond STARVED_SLACK (its toggles and checks came late)


class _Listener(can.Listener):
    # on a redundant pair it reads rx_line() only in the line selection's gates, which the pair
    # turns off while every node is on one line (base/transport/rx_gating.py)
    rx_line_gated = True

    def __init__(self, sim: "Simulator"):
        self.sim = sim

    def on_message_received(self, msg: can.Message) -> None:
        try:
            self.sim._route(msg)
        except Exception:  # never let one frame kill the receive thread
            self.sim.stats.internal_errors += 1
            logger.exception("simulator: error handling frame %s", msg)

    def on_frame(self, can_id: int, data: bytes, timestamp: float) -> None:
        """Inline hot path: a standard data frame as plain values (no Message)."""
        self.sim._route_frames(((can_id, data),))

    def on_frames(self, frames, timestamp: float) -> None:
        """In-process bus: a burst of standard data frames (a cycle's RPDOs, a SYNC) in one call."""
        self.sim._route_frames(frames)

    def on_error(self, exc: Exception) -> None:
        self.sim.stats.internal_errors += 1
        logger.error("simulator: bus error %s", exc)


class Simulator:
    def __init__(self, bus_spec: str, bus_config: BusConfig | str | Path = DEFAULT_BUS_CONFIG,
                 plant: Plant | PlantConfig | str | Path | None = None, control_node_id: int | None = None,
                 diag_node_id: int | None = peer_timing.SIMULATOR_DIAG_NODE, time_base: str = "wall"):
        """time_base: "wall" (real time: heartbeat consumers judge on the monotonic clock) or
        "sync" (beside a lockstep controller: they judge on SYNC time, the plant's clock, and
        heartbeats fall due on it as well; _sync_time_timers)."""
        if time_base not in ("wall", "sync"):
            raise ValueError(f"time base must be 'wall' or 'sync', got {time_base!r}")
        self.sync_time_base = time_base == "sync"
        self._next_sync_heartbeat: dict[int, float] = {}
        self.bus_spec = bus_spec
        self.config = bus_config if isinstance(bus_config, BusConfig) else load_bus_config(bus_config)
        if isinstance(plant, Plant):
            self.plant = plant
        else:
            plant_config = plant if isinstance(plant, PlantConfig) else load_plant_config(plant)
            self.plant = Plant.create(len(self.config.joints), plant_config)
        # the drive and the master must count the same units: a linear axis has a feed constant
        check_axis_kinds(self.config, [j.params.kind for j in self.plant.joints], "the plant")
        self.dt = self.config.bus.sync_period
        self.nodes: dict[int, SimNode] = {}
        joint_index = 0
        for cfg in self.config.nodes:
            if cfg.device == "joint_drive":
                node = JointDriveNode(cfg.node_id, cfg.eds_path, cfg.name, self.plant, joint_index)
                joint_index += 1
            elif cfg.device == "end_effector":
                node = EndEffectorNode(cfg.node_id, cfg.eds_path, cfg.name, self.plant)
            else:
                node = FtSensorNode(cfg.node_id, cfg.eds_path, cfg.name, self.plant)
            node._send = self._send
            node._send_many = self._send_many
            node.pdo_changed_callback = self._mark_dirty
            self.nodes[cfg.node_id] = node
        self._tpdo_direct = {node: _tpdo_route(node, node._send_many) for node in self.nodes.values()}
        self.control = None
        if control_node_id is not None:
            from spacearm.firmware_sim.control import SimControlNode
            if control_node_id in self.nodes:
                raise ValueError(f"control node ID {control_node_id} is used by a device of the bus config")
            self.control = SimControlNode(control_node_id, self)
        self.laser = None
        if self.plant.config.laser is not None:
            from spacearm.firmware_sim.laser_ranger import LaserRangerSim, tool_plane_distance
            target = self.plant.config.laser
            self.laser = LaserRangerSim(tool_plane_distance(self.plant.tool_pose, target.plane[:3], target.plane[3]),
                                        target.ranger_config())
        self.camera = None        # spacearm.firmware_sim.camera.service.CameraService, see attach_camera
        self.stats = SimStats()
        # this process's own lateness, published as the TPDO of a diagnostics node (None: off)
        if diag_node_id in self.nodes:
            logger.warning("simulator: node ID %d is a device of the bus config; no timing reports", diag_node_id)
            diag_node_id = None
        self.diag_node_id = diag_node_id
        # What a late wake waited for (the process's threads' /proc schedstat, the host's steal)
        # explains a real-time simulator's lateness; beside a lockstep controller nothing waits
        # for this timer, and each of those reads hands the GIL back and forth with the cycle
        # thread (issue 35: half the timer's CPU beside lockstep cycles). Counts and the worst
        # lateness are still reported.
        self.lateness = peer_timing.LatenessMeter(measure_causes=not self.sync_time_base)
        self.cpu_samples: list[float] | None = None   # set to [] to record the CPU s of every SYNC (benchmarks)
        self.bus: can.BusABC | None = None
        self._notifier: can.Notifier | None = None
        self._send_lock = threading.Lock()
        # frames a SYNC's handling sends (TPDOs, a due heartbeat) are collected and written as
        # one burst (one write on the loopback bus); only the thread handling the SYNC batches
        self._batch: list[tuple[int, bytes]] | None = None
        self._batch_thread: int | None = None
        self._sync_lock = threading.Lock()
        self._dirty = True
        self._rpdo_routes: dict[int, SimNode] = {}
        self._rpdo_direct: dict[int, tuple] = {}     # the routes rpdo_burst takes (_direct_route)
        self._sync_ids: set[int] = {od.SYNC_COB_ID_DEFAULT}
        self._stop = threading.Event()
        self._hb_thread: threading.Thread | None = None
        self.line_selection = None    # line_selection.LineSelection on a redundant pair (start)

    # ------------------------------------------------------------------ public
    def start(self) -> "Simulator":
        self.bus = open_bus(self.bus_spec)
        self._send_frame = frame_sender(self.bus)
        self._send_frames = frames_sender(self.bus)
        listener = _Listener(self)
        self._notifier = can.Notifier(self.bus, [listener], timeout=0.1)
        if hasattr(self.bus, "add_inline_listener"):
            self.bus.add_inline_listener(listener)   # in-process bus: no thread hop per frame
        self.line_selection = line_selection.attach(self)   # each node on its own line of a pair
        for node in self.nodes.values():
            node.power_on()                       # each sends its boot-up message
        self._hb_thread = threading.Thread(target=self._heartbeat_loop, name="sim-heartbeat", daemon=True)
        self._hb_thread.start()
        if self.laser is not None:
            self.laser.start()
        return self

    def attach_camera(self, sink, scene=None, frame_rate: float | None = None, render_process: bool | None = None):
        """Serve the eye-in-hand camera from this plant into `sink` (ShmFrameRing for another
        process, LocalFrameSource in-process). render_process (default: whenever the sink is a
        shared-memory ring) renders in a child process (firmware_sim/camera/render_process.py):
        a render thread here, at normal priority, held the GIL the nodes' SCHED_FIFO threads
        wait for and was preempted holding it by any other process, a priority inversion that
        made the nodes 100+ ms late beside two CPU-bound processes (bench/bench_realtime.py gil).
        A LocalFrameSource (in-process tests) renders on a thread here."""
        from spacearm.firmware_sim.camera.service import CameraService
        from spacearm.base.config.scene import DEFAULT_SCENE
        # the camera sees the cell the contact world is built from (the plant's store errors included)
        scene = scene or getattr(self.plant.environment, "scene", None) or DEFAULT_SCENE
        self.camera = CameraService.from_files(self.plant, sink, scene, frame_rate)
        if render_process is None:
            render_process = hasattr(sink, "name")
        if render_process:
            self.camera.use_render_process()
        self.camera.start()
        return self.camera

    def stop(self) -> None:
        self._stop.set()
        if self.camera is not None:
            self.camera.stop()
        if self.laser is not None:
            self.laser.stop()
        if self._hb_thread is not None:
            self._hb_thread.join(1.0)
        if self._notifier is not None:
            self._notifier.stop(1.0)
        for node in self.nodes.values():
            node.powered = False
        if self.bus is not None:
            self.bus.shutdown()
            self.bus = None

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()

    def node(self, name_or_id: str | int) -> SimNode:
        for node in self.nodes.values():
            if node.name == name_or_id or node.node_id == name_or_id:
                return node
        raise KeyError(f"no simulated node {name_or_id!r}")

    def power_cycle(self, name_or_id: str | int) -> None:
        """Fault injection / recovery: the node reboots (boot-up message, PRE-OPERATIONAL)."""
        node = self.node(name_or_id)
        node.faults.silent = False
        with self._sync_lock:
            node.power_on()

    # ------------------------------------------------------------------ internals
    def _send(self, can_id: int, data: bytes) -> None:
        if self.bus is None:
            return
        if self._batch is not None and self._batch_thread == threading.get_ident():
            self._batch.append((can_id, data))
            return
        with self._send_lock:
            try:
                self._send_frame(can_id, data)
            except can.CanError as exc:
                logger.warning("simulator: send failed: %s", exc)

    def _send_many(self, frames: list[tuple[int, bytes]]) -> None:
        if self.bus is None:
            return
        if self._batch is not None and self._batch_thread == threading.get_ident():
            self._batch.extend(frames)
            return
        for can_id, data in frames:
            self._send(can_id, data)

    def _flush_batch(self) -> None:
        frames, self._batch, self._batch_thread = self._batch, None, None
        if frames and self.bus is not None:
            with self._send_lock:
                try:
                    self._send_frames(frames)
                except can.CanError as exc:
                    logger.warning("simulator: send failed: %s", exc)

    def _mark_dirty(self) -> None:
        self._dirty = True

    def _rebuild_routes(self) -> None:
        self._dirty = False
        routes: dict[int, SimNode] = {}
        syncs = set()
        for node in self.nodes.values():
            node._routing_dirty = False
            if not node.powered:
                continue
            for cob in node.rpdo_cob_ids():
                routes[cob] = node
            syncs.add(node.sync_cob_id())
        self._sync_ids = syncs or {od.SYNC_COB_ID_DEFAULT}
        # _route_data looks RPDOs up first; a COB-ID that names another service keeps that
        # meaning, as in the service-by-service order below
        self._rpdo_routes = {cob: node for cob, node in routes.items()
                             if cob != od.NMT_COB_ID and cob not in self._sync_ids
                             and not od.SDO_RX_BASE < cob <= od.SDO_RX_BASE + 127
                             and not od.HEARTBEAT_BASE < cob <= od.HEARTBEAT_BASE + 127}
        direct = ((cob, _direct_route(node)) for cob, node in self._rpdo_routes.items())
        self._rpdo_direct = {cob: route for cob, route in direct if route is not None}

    def _route(self, msg: can.Message) -> None:
        self.stats.rx_frames += 1
        if msg.is_remote_frame and not msg.is_extended_id and msg.arbitration_id & ~0x7F == od.HEARTBEAT_BASE:
            node = self.nodes.get(msg.arbitration_id & 0x7F)     # node guarding request
            if node is not None and node.powered and not node.faults.silent:
                node.on_guard_request()
            return
        if msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id or getattr(msg, "is_fd", False):
            self.stats.ignored += 1
            return
        self._route_data(msg.arbitration_id, bytes(msg.data), counted=True)

    def _route_frames(self, frames) -> None:
        """Standard data frames in order, none raising. With the compiled core, a run of RPDOs
        that take the direct path (_direct_route) is stored in one call under one hold of the
        SYNC lock (issue 35: ~2 us of Python per RPDO, 14 a cycle); the rest as _route_each."""
        core = simcore.core
        if core is None:
            self._route_each(frames)
            return
        i, n = 0, len(frames)
        while i < n:
            if not self._dirty and self._rpdo_direct:
                with self._sync_lock:
                    done = core.rpdo_burst(frames, i, self._rpdo_direct, self.stats, SdoAbortedError,
                                           od.NMT_STATE_OPERATIONAL)
                if done.__class__ is tuple:       # frame i raised: the others go on
                    i, exc = done
                    self._frame_failed(frames[i], exc)
                    i += 1
                    continue
                i = done
                if i >= n:
                    return
            self._route_each((frames[i],))
            i += 1

    def _route_each(self, frames) -> None:
        """Frame by frame: an RPDO of a live node with the routes up to date goes to it here,
        without _route_data's call (most of the frames a cycle brings); anything else, and any
        RPDO while the routes are stale, goes to _route_data."""
        stats = self.stats
        for cid, data in frames:
            try:
                node = None if self._dirty else self._rpdo_routes.get(cid)
                if node is None or not node.powered or node.faults.silent:
                    self._route_data(cid, data)
                    continue
                stats.rx_frames += 1
                node.stats.rx_frames += 1
                with self._sync_lock:
                    node.on_rpdo(cid, data)
            except Exception as exc:  # never let one frame fail the sender or the rest of the burst
                self._frame_failed((cid, data), exc)

    def _frame_failed(self, frame, exc: Exception) -> None:
        self.stats.internal_errors += 1
        logger.error("simulator: error handling frame 0x%03X %s", frame[0], bytes(frame[1]).hex(), exc_info=exc)

    def _route_data(self, cid: int, data: bytes, counted: bool = False) -> None:
        """A standard data frame: dispatch by COB-ID (PDOs first: they are most of the traffic)."""
        if not counted:
            self.stats.rx_frames += 1
        if self._dirty and not _never_rpdo(cid):
            self._rebuild_routes()      # not for every SDO of a PDO configuration: one at its end
        node = self._rpdo_routes.get(cid)
        if node is not None:
            if node.powered and not node.faults.silent:
                node.stats.rx_frames += 1
                with self._sync_lock:
                    node.on_rpdo(cid, data)
            return
        if cid == od.NMT_COB_ID:
            if len(data) != 2:
                self.stats.malformed += 1
                return
            command, target = data[0], data[1]
            with self._sync_lock:
                for node in self.nodes.values():
                    if (target == 0 or target == node.node_id) and node.powered and not node.faults.silent:
                        node.stats.rx_frames += 1
                        node.on_nmt(command)
            self._dirty = True
        elif cid in self._sync_ids:
            if len(data) > 1:
                self.stats.malformed += 1
                return
            self._on_sync()
        elif od.SDO_RX_BASE < cid <= od.SDO_RX_BASE + 127:
            node = self.nodes.get(cid - od.SDO_RX_BASE)
            if node is None and self.control is not None and cid - od.SDO_RX_BASE == self.control.node_id:
                self.control.on_sdo_request(data)
            elif node is None:
                self.stats.unknown += 1
            elif node.powered and not node.faults.silent:
                node.stats.rx_frames += 1
                with self._sync_lock:
                    node.on_sdo_request(data)
                if node._routing_dirty:
                    self._dirty = True
        elif od.HEARTBEAT_BASE < cid <= od.HEARTBEAT_BASE + 127:
            if len(data) != 1:
                self.stats.malformed += 1
                return
            now = self.plant.time if self.sync_time_base else time.monotonic()
            for node in self.nodes.values():
                if node.powered and not node.faults.silent:
                    node.on_heartbeat(cid - od.HEARTBEAT_BASE, now)
        else:
            self.stats.unknown += 1

    def _on_sync(self) -> None:
        samples = self.cpu_samples
        started = time.thread_time() if samples is not None else 0.0
        self._on_sync_locked()
        if samples is not None:
            samples.append(time.thread_time() - started)

    def _on_sync_locked(self) -> None:
        with self._sync_lock:
            self._batch, self._batch_thread = [], threading.get_ident()
            try:
                self._sync_step()
            finally:
                self._flush_batch()

    def _sync_step(self) -> None:
        """One SYNC under the SYNC lock: physics, then every node's TPDOs and due heartbeats."""
        self.stats.syncs += 1
        nodes = [n for n in self.nodes.values() if n.powered]
        # one SYNC period of physics: the period the controller configured (1006h), else the
        # bus config's
        dt = self.dt
        for node in nodes:
            period = node.param(od.COMM_CYCLE_PERIOD)
            if period > 0:
                dt = period / 1e6
                break
        for node in nodes:
            node.on_sync_begin(dt)
        self.plant.step(dt)
        if self.camera is not None:       # exposure snapshot only; rendering is on its own thread
            self.camera.on_sync(self.stats.syncs)
        for node in nodes:
            node.on_sync_end(dt)
        self._send_tpdos(nodes)
        # A heartbeat that fell due is sent here too: the SYNC thread runs anyway, so a
        # timer thread starved of the GIL does not delay it (whichever runs first sends).
        now = time.monotonic()
        for node in nodes:
            if 0.0 < node.next_heartbeat <= now and node.nmt_state != od.NMT_STATE_BOOTUP:
                self._heartbeat_due(node, now)
        if self.sync_time_base:
            self._sync_time_timers(nodes)

    def _send_tpdos(self, nodes: list[SimNode]) -> None:
        """Every live node's SYNC TPDOs into this SYNC's burst, in node order. With the compiled
        core the nodes on its direct path (_tpdo_route) are sampled and batched in one call
        (issue 35: five Python calls per node and SYNC around the core's tpdo_frames); any
        other node, and every node without the core, through its send_tpdos."""
        core = simcore.core
        batching = self.bus is not None and self._batch is not None and self._batch_thread == threading.get_ident()
        i, n = 0, len(nodes)
        while i < n:
            if core is not None and batching:
                i = core.tpdo_burst(nodes, i, self._tpdo_direct, self._batch, od.NMT_STATE_OPERATIONAL)
                if i >= n:
                    return
            node = nodes[i]
            if not node.faults.silent:
                node.send_tpdos()
            i += 1

    def _sync_time_timers(self, nodes: list[SimNode]) -> None:
        """SYNC time base: heartbeats fall due, and consumed heartbeats are judged, on the
        plant's clock. A lockstep controller's process that waits for a core stops the SYNCs
        and with them this clock, so its silence is never a lost heartbeat; the wall-clock
        producer goes on beside it (a consumer on either clock is served)."""
        now = self.plant.time
        for node in nodes:
            if node.nmt_state == od.NMT_STATE_BOOTUP or node.faults.silent:
                continue
            consumed = node.consumer_last
            if consumed and not _consumers_quiet(node, consumed, now):
                node.check_consumers(now)
            # heartbeat_period() with param()'s cached value inline: every node, every SYNC
            period = node._params.get(_HEARTBEAT_KEY)
            period = (node.param(od.PRODUCER_HEARTBEAT) if period is None else period) / 1000.0
            if period <= 0.0:
                continue
            due = self._next_sync_heartbeat.setdefault(node.node_id, now + period)
            if now >= due - 1e-9:
                node.send_heartbeat()
                self._next_sync_heartbeat[node.node_id] = max(due + period, now)
        if self.line_selection is not None:
            self.line_selection.timer_pass(locked=True)    # a toggle falls due on this clock too

    def _heartbeat_loop(self) -> None:
        """The nodes' one timer scheduler: heartbeats, event-timer TPDOs, heartbeat consumers
        and SDO server timeouts. It sleeps until the earliest heartbeat or event timer is due
        (at most TIMER_MAX_SLEEP, the resolution of consumer and SDO timeouts;
        TIMER_MAX_SLEEP_SYNC on the SYNC time base) instead of polling, so it takes the GIL a
        few times per heartbeat period, not 500 times a second.

        Starvation: when this thread wakes more than STARVED_SLACK after it meant to (the host
        or this process's other threads held the CPU), the excess was time nobody here could
        observe the bus; it is not counted as silence of a consumed heartbeat (SimNode.
        excuse_consumers, at most half the consumer timeout per silence), so a starved
        simulator does not fault its drives for a controller that was alive. A controller
        that really stopped is still caught: every unstarved scheduler pass counts in full."""
        # On the SYNC time base consumers are judged at the SYNCs: what is left on this clock
        # (SDO server timeouts of 1 s; heartbeats, event timers and reports wake it when due)
        # needs no 10 ms resolution, and each pass beside lockstep cycles takes the GIL from
        # the cycle thread (issue 35: ~100 passes a second, 0.3-0.5 ms of CPU each)
        max_sleep = TIMER_MAX_SLEEP_SYNC if self.sync_time_base else TIMER_MAX_SLEEP
        due = time.monotonic()
        while not self._stop.is_set():
            now, cpu_at_start = time.monotonic(), time.thread_time()
            self.lateness.woke(now - due, now)
            excess = now - due - STARVED_SLACK
            starved = excess > 0
            if starved:
                self.stats.starved_time += excess
                for node in self.nodes.values() if not self.sync_time_base else ():
                    if node.consumer_last:
                        node.excuse_consumers(excess)
            # a starved pass sends what is due but judges no consumer: the next pass does, soon
            wake = now + (TIMER_MIN_SLEEP * 6 if starved else max_sleep)
            for node in list(self.nodes.values()):
                if not node.powered or node.nmt_state == od.NMT_STATE_BOOTUP:
                    continue
                if node.consumer_last and not node.faults.silent and not starved and not self.sync_time_base:
                    with self._sync_lock:
                        node.check_consumers(now)
                node.check_sdo_timeout(now)
                if node.has_event_tpdos:
                    with self._sync_lock:
                        node.send_event_tpdos(now)
                    for pdo in node._tpdos or ():
                        if pdo.next_event > 0.0:
                            wake = min(wake, pdo.next_event)
                due_hb = self._heartbeat_pending(node, now)
                if due_hb is None:
                    with self._sync_lock:
                        due_hb = self._heartbeat_due(node, now)
                if due_hb:
                    wake = min(wake, due_hb)
            selection = self.line_selection
            # on the SYNC time base the nodes toggle at a SYNC only (_sync_time_heartbeats): a
            # wall-clock pass between two SYNCs would toggle them where the machine's speed says
            if selection is not None and not self.sync_time_base and selection.timer_pass():
                wake = min(wake, now + line_selection.TICK)
            if self.diag_node_id is not None:
                if self.lateness.due(now):
                    self._send(od.TPDO_BASE[0] + self.diag_node_id, self.lateness.report(now))
                wake = min(wake, self.lateness.next_due())
            # A pass that costs more than the sleep it was sized for (a machine many times
            # slower, e.g. the test VM's software emulation) must not turn this SCHED_FIFO thread
            # into a busy loop that starves every normal-priority process on its core, the
            # controller among them (measured: a whole vCPU, SDO answers and TPDOs on the bus
            # for 8 s before the controller ran): it sleeps at least TIMER_DUTY_SLEEP times the
            # CPU its pass used. CPU, not wall time: a pass that waited for the GIL or a held
            # vCPU used nothing, and sleeping twice that wait would only make its heartbeats late.
            cpu = time.thread_time() - cpu_at_start
            end = time.monotonic()
            # a pass preempted, or waiting for the SYNC lock behind a preempted thread, judged
            # and toggled late without waking late (a CI run: a node's line toggle 200 ms late)
            self.stats.held_time += max(0.0, end - now - STARVED_SLACK)
            due = max(wake, now + TIMER_MIN_SLEEP, end + cpu * TIMER_DUTY_SLEEP)
            self._stop.wait(max(0.0, due - end))

    @staticmethod
    def _heartbeat_pending(node: SimNode, now: float) -> float | None:
        """When the node's running heartbeat falls due, if not yet; None: _heartbeat_due has
        something to do (send it, start or stop the producer). Asked without the SYNC lock:
        each acquisition while the SYNC thread holds it costs the timer thread GIL hand-overs
        (issue 35: most of a pass's CPU beside lockstep cycles, a lock per node and pass). The
        SYNC thread may send the heartbeat meanwhile; _heartbeat_due then finds it sent."""
        due = node.next_heartbeat
        try:
            return due if 0.0 < now < due and node.heartbeat_period() > 0.0 else None
        except Exception:       # _heartbeat_due's answer to a period it cannot read
            return None

    def _heartbeat_due(self, node: SimNode, now: float) -> float:
        """Send the node's heartbeat if due; returns when the next one is due (0: none)."""
        try:
            period = node.heartbeat_period()
        except Exception:
            return 0.0
        if period <= 0.0:
            node.next_heartbeat = 0.0
            return 0.0
        if node.next_heartbeat == 0.0:
            node.next_heartbeat = now + period
        elif now >= node.next_heartbeat:
            node.send_heartbeat()
            node.next_heartbeat = max(node.next_heartbeat + period, now)
        return node.next_heartbeat


# The timer scheduler's sleep bounds: consumer and SDO timeouts are checked at least every
# TIMER_MAX_SLEEP; a wake later than STARVED_SLACK past its due time counts as starvation.
TIMER_MAX_SLEEP = 0.010   # s
TIMER_MAX_SLEEP_SYNC = 0.050   # s: the same on the SYNC time base (SDO timeouts only: 5 % of 1 s)
TIMER_MIN_SLEEP = 0.0005  # s
STARVED_SLACK = 0.020     # s
TIMER_DUTY_SLEEP = 2.0    # sleep >= 2x the pass's CPU: the timer takes at most a third of a core


def start_simulator(bus_spec: str, bus_config: BusConfig | str | Path = DEFAULT_BUS_CONFIG,
                    plant: Plant | PlantConfig | str | Path | None = None,
                    control_node_id: int | None = None,
                    diag_node_id: int | None = peer_timing.SIMULATOR_DIAG_NODE,
                    time_base: str = "wall") -> Simulator:
    """Start all simulated nodes of the bus config on the bus; returns the handle (.stop()).
    control_node_id: also serve the fault-injection unit (spacearm.firmware_sim.control) at this ID;
    time_base: "sync" beside a lockstep controller (Simulator)."""
    return Simulator(bus_spec, bus_config, plant, control_node_id, diag_node_id, time_base).start()
