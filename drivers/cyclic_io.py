"""Cyclic I/O of the network: SYNC, RPDOs out, TPDOs in, their supervision, and the state in
SI units. ``CyclicIO`` is a part of ``ArmNetwork`` (drivers/network.py) and works on its
drivers, health, stats and condition variable; it never sleeps except the optional lockstep
wait for a SYNC's TPDOs.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Sequence

from spacearm.base.canopen import od
from spacearm.drivers.devices import (DeviceDriver, EeCommand, EndEffectorState, FtState, JointDriver, JointState,
                                      PdoCodec)
from spacearm.drivers.errors import DriverError, emcy_text
from spacearm.drivers.health import NodeHealth
from spacearm.base.canopen.cia402_defs import State
from spacearm.drivers.tpdo_burst import MAX_PLANS, build_plan, first, second

logger = logging.getLogger(__name__)
_NO_PLAN_YET = object()     # a burst's COB-ID sequence not seen before (None: seen, no plan)
_new = object.__new__


@dataclass
class ArmState:
    sync: int                        # SYNC number this state belongs to
    complete: bool                   # every expected TPDO of this SYNC arrived
    joints: list[JointState]
    end_effector: EndEffectorState | None
    ft: FtState | None
    nodes: dict[str, NodeHealth]
    # read(joints=False): per joint (position, velocity, torque, state) instead of `joints`
    readings: list[tuple[float, float, float, State]] | None = None

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




class CyclicIO:
    # ------------------------------------------------------------------ cycle API
    def send_sync(self) -> int:
        """Send one SYNC; returns its number. TPDOs arriving from now on belong to it."""
        with self._lock:
            expected = self._expected_tpdos()
            if self._expected is not None and self._monitoring:
                self._count_missing_tpdos(expected - self._received)
            self._note_answers(expected)
            self._sync += 1
            if self.controller_period is not None:
                # the set is worked out again only where the health check changed a node (it
                # clears _expected whenever it declares one lost; under the lock nothing else
                # runs meanwhile): the same set, one pass over the nodes a cycle less (issue 35)
                self._expected = expected
                self._lockstep_health(time.monotonic())
                if self._expected is None:
                    expected = self._expected_tpdos()
            self._received = set()
            self._expected = expected
            self.stats.expected_tpdos += len(self._expected)
        if self.controller_period is not None:
            self._send_lockstep_heartbeat()
        elif self._monitor is not None:
            self._own_heartbeat_if_due(time.monotonic())    # if the timer has not sent it yet
        # False only on a redundant pair whose line fault kept the SYNC off (never acknowledged)
        self._sync_kept_off = self._send(od.SYNC_COB_ID_DEFAULT, b"") is False
        self.stats.syncs_sent += 1
        self.stats.syncs_kept_off += self._sync_kept_off
        return self._sync

    def _note_answers(self, expected: set[int]) -> None:
        """Which nodes answered the SYNC now ending: every TPDO of theirs it asked for arrived
        before the next one goes out, however late in the period (answered_last_sync)."""
        owner = self._tpdo_owner
        answered = self._owners_of.get(expected)
        if answered is None:        # a set of live nodes not seen before (a few per run)
            answered = self._owners_of[expected] = frozenset(owner[cob] for cob in expected)
        missing = expected - self._received
        self._answered = answered - {owner[cob] for cob in missing} if missing else answered

    def answered_last_sync(self, names) -> list[str]:
        """Of `names`, the nodes that answered the previous SYNC before this one went out.
        A node missing at a real-time read whose data came later in the same period was slow
        (it, the bus or this process), not silent: its TPDO is the evidence it is alive."""
        with self._lock:
            return [name for name in names if name in self._answered]

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

    def _expected_tpdos(self) -> frozenset[int]:
        # the per-node sets are built with the routes (drivers/network.py), from the layouts
        return frozenset().union(*[cobs for h, cobs in self._tpdo_nodes
                                   if h.alive and h.nmt_state == od.NMT_STATE_OPERATIONAL])

    def wait_all_tpdos(self, timeout: float | None = None) -> bool:
        """Lockstep: wait until every live OPERATIONAL node sent this SYNC's TPDOs."""
        if self._sync_kept_off:
            # No node got this SYNC (a cut or stuck line), so none will answer it: waiting out the
            # timeout would only cost wall time (a lockstep cycle on a cut line in the vcan VM:
            # 7.5 s), and it is no observed silence of any node.
            return False
        timeout = self.config.bus.lockstep_timeout if timeout is None else timeout
        with self._lock:
            # in-process, every answer came during the SYNC's send: no wait to set up
            ok = self._expected_tpdos() <= self._received or self._cv.wait_for(
                lambda: self._expected_tpdos() <= self._received, timeout=timeout)
        if not ok:
            self.stats.tpdo_timeouts += 1
            self._lockstep_wait_expired = timeout     # observed silence (health.py _lockstep_health)
        return ok

    def write(self, command: ArmCommand | None = None) -> None:
        """Apply a command (SI units), advance the drivers' state machines one step from the
        latest TPDOs and send the RPDOs. Call before send_sync()."""
        if not self._connected:
            raise DriverError("the network is not connected: call boot() first")
        if command is not None:
            self._apply(command)
        frames = []
        append, bringup, operational = frames.append, self.bringup, od.NMT_STATE_OPERATIONAL
        with self._lock:
            for d, joint, h in self._cycle_drivers:
                if joint:
                    report = bringup.get(d.name)
                    if report is not None and report.master_following_error:
                        self._check_following_error(d)
                    # the RPDOs packed from the values the step computed (drivers/joint_rpdos.py)
                    packed = d.step_frames()
                    axis = d.axis
                    if axis.fault_reset_failed:
                        axis.fault_reset_failed = False
                        self._event("fault_reset_failed", d,
                                    f"{d.label}: fault reset did not clear the fault "
                                    f"(error 0x{d.value(od.ERROR_CODE):04X} {emcy_text(d.value(od.ERROR_CODE))})",
                                    d.value(od.ERROR_CODE))
                        packed = None    # packed again below: an event's callback may change a value
                    if axis.fault_cleared:
                        self._event("fault_cleared", d, f"{d.label}: fault cleared")
                        packed = None
                else:
                    d.step()
                    packed = None
                # Also to a node whose heartbeat was lost: it may still listen (only its
                # heartbeat producer failed), and the protective stop must reach it.
                if h.nmt_state == operational:
                    packs = d.rpdo_packs     # rpdo_frames' common case, without a call per driver
                    if packed is not None:
                        frames += packed
                    elif packs is None:
                        frames += d.rpdo_frames()
                    else:
                        get = d.rpdo_values.get
                        for cob_id, pack, keys, zeros in packs:
                            append((cob_id, pack(*map(get, keys, zeros))))
        if frames:
            if not self._connected:
                raise DriverError("the network is not connected: call boot() first")
            with self.network.send_lock:
                self._send_frames(frames)      # one write on the loopback bus

    def _check_following_error(self, d: JointDriver) -> None:
        """The fallback for a drive without a following-error window (6065h/6066h absent or
        refused): the position the drive reports against the target sent one SYNC earlier, over
        the bus file's window for longer than its timeout, is a ``following_error`` event
        (once per excursion) with the CiA 402 code 8611h."""
        if not d.axis.enabled or (od.TARGET_POSITION, 0) not in d.rpdo_values:
            self._following_over.pop(d.name, None)
            return
        error = abs(d.rpdo_values[(od.TARGET_POSITION, 0)] / d.k - d.position)
        s = d.settings
        if error <= s.following_error_window:
            self._following_over.pop(d.name, None)
            return
        cycles = self._following_over[d.name] = self._following_over.get(d.name, 0) + 1
        if cycles == max(1, round(s.following_error_timeout / self.config.bus.sync_period)) + 1:
            self._event("following_error", d, f"{d.label}: following error {error:.6g} beyond the window "
                                              f"{s.following_error_window:g} for {s.following_error_timeout:g} s "
                                              f"(supervised by the master: the drive has no 6065h)",
                        od.EMCY_FOLLOWING_ERROR)

    def _send(self, can_id: int, data: bytes) -> bool | None:
        """The cycle's frames (SYNC, RPDOs): plain values to the bus, no Message on the
        in-process bus; the library's send lock keeps them whole against SDO/NMT senders.
        Returns the transport's answer: False when a redundant pair's line fault kept the
        frame off, None where the transport cannot tell."""
        if not self._connected:
            raise DriverError("the network is not connected: call boot() first")
        with self.network.send_lock:
            return self._send_frame(can_id, data)

    def _apply(self, c: ArmCommand) -> None:
        # one pass per given sequence, up to the shorter of it and the joints (zip), not three
        # tests and lengths per joint (issue 35): the same assignments in the same order per field
        joints = self.joints
        if c.joint_positions is not None:
            for j, position in zip(joints, c.joint_positions):
                if position is not None:
                    j.target = float(position)
        if c.joint_velocities is not None:
            for j, velocity in zip(joints, c.joint_velocities):
                j.velocity_ff = float(velocity)
        if c.joint_torques is not None:
            for j, torque in zip(joints, c.joint_torques):
                j.torque_ff = float(torque)
        if c.end_effector is not None and self.end_effector is not None:
            self.end_effector.command(c.end_effector)

    def nodes_missing_tpdos(self) -> list[str]:
        """Names of live nodes whose TPDOs of the current SYNC have not all arrived."""
        with self._lock:
            missing = self._expected_tpdos() - self._received
            return sorted({self._tpdo_owner[cob] for cob in missing})

    def tpdos_complete(self) -> bool:
        """Have all expected TPDOs of the last SYNC arrived (non-blocking)?"""
        with self._lock:
            return self._expected_tpdos() <= self._received

    def read(self, complete: bool | None = None, nodes: bool = True, joints: bool = True) -> ArmState:
        """The latest values in SI units (non-blocking). ``complete`` defaults to
        tpdos_complete(): whether they all belong to the last SYNC. ``nodes=False`` leaves
        ArmState.nodes empty, for a caller that reads the nodes' health only when data is
        missing (the daemon's cycle: a snapshot per node every cycle it never looked at).
        ``joints=False`` leaves ArmState.joints empty and gives ArmState.readings instead:
        the four values per joint the daemon's Measurement takes, without a JointState each."""
        with self._lock:
            if complete is None:
                complete = self._expected_tpdos() <= self._received
            # every cycle: the fields in ArmState's order without its __init__'s keyword handling
            state = _new(ArmState)
            state.__dict__ = {
                "sync": self._sync, "complete": complete,
                "joints": [j.state() for j in self.joints] if joints else [],
                "end_effector": self.end_effector.state() if self.end_effector else None,
                "ft": self.ft.state() if self.ft else None,
                "nodes": {n: h.snapshot() for n, h in self.health.items()} if nodes else {},
                "readings": None if joints else [j.reading() for j in self.joints]}
            return state

    def cycle(self, command: ArmCommand | None = None, wait: bool = True,
              timeout: float | None = None) -> ArmState:
        """One control cycle: write(command), send_sync(), [wait_all_tpdos()], read()."""
        self.write(command)
        self.send_sync()
        if wait:
            self.wait_all_tpdos(timeout)
        return self.read()



    def _receive_frame(self, can_id: int, data, timestamp: float) -> None:
        """Every standard data frame the network receives one at a time (its listener's
        on_frame, never raises)."""
        self._receive_frames(((can_id, data),), timestamp)

    def _receive_frames(self, frames, timestamp: float) -> None:
        """Standard data frames in order (the in-process bus hands a SYNC's TPDOs over as one
        burst: the listener's on_frames; never raises). A TPDO is decoded here, with its compiled
        route, and a burst's TPDOs under one hold of the lock (one acquire, one wake-up check per
        burst, not per frame); anything else goes to _other_frame, outside the lock. A burst
        with a plan (a SYNC's TPDOs, drivers/tpdo_burst.py) is decoded node by node instead."""
        if len(frames) > 1 and self._decode_burst(frames):
            return
        stats, routes, lock = self.stats, self._tpdo_in, self._lock
        held = False
        decoded = 0      # counted once a hold ends: per frame it is two attribute writes more
        try:
            for can_id, data in frames:
                route = routes.get(can_id)
                if route is None or route.unpack is None or len(data) < route.length:
                    if held:
                        held = False
                        stats.rx_frames += decoded
                        stats.tpdos += decoded
                        decoded = 0
                        self._wake_if_complete()
                        lock.release()
                    self._other_frame(can_id, data, timestamp)
                    continue
                if not held:
                    lock.acquire()
                    held = True
                    sync, arrived = self._sync, self._received.add   # fixed while the lock is held
                try:   # the common case: one unpack per frame
                    route.driver.values.update(zip(route.keys, route.unpack(data)))
                    route.health.life_sync = sync
                    arrived(can_id)
                    decoded += 1
                except Exception:
                    stats.rx_frames += 1
                    stats.callback_errors += 1
                    logger.exception("error handling frame 0x%03X", can_id)
        finally:
            if held:
                stats.rx_frames += decoded
                stats.tpdos += decoded
                self._wake_if_complete()
                lock.release()

    def _decode_burst(self, frames) -> bool:
        """A burst of compiled TPDOs in a known order and of their PDOs' lengths: each node's
        values in one unpack from the joined payloads, the health and the arrived set updated
        once per node and per burst. False (nothing done) where the per-frame path must run."""
        ids = tuple(map(first, frames))
        plans = self._burst_plans
        plan = plans.get(ids, _NO_PLAN_YET)
        if plan is _NO_PLAN_YET:
            if len(plans) >= MAX_PLANS:
                plans.clear()
            try:
                plan = build_plan(ids, self._tpdo_in)
            except Exception:     # a bug here must not cost the frames: said once, frame by frame after
                logger.exception("no TPDO burst plan for COB-IDs %s: decoding them frame by frame",
                                 " ".join(f"0x{cob:03X}" for cob in ids))
                plan = None
            plans[ids] = plan
        if plan is None:
            return False
        payloads = tuple(map(second, frames))
        if tuple(map(len, payloads)) != plan.lengths:
            return False
        joined = b"".join(payloads)
        stats, count = self.stats, plan.count
        with self._lock:
            sync = self._sync
            for node in plan.nodes:
                driver = node.driver
                if node.keys is driver.tpdo_keys:    # every TPDO of the node: kept as one tuple
                    driver.latest = node.unpack(joined, node.offset)
                else:
                    driver.values.update(zip(node.keys, node.unpack(joined, node.offset)))
                node.health.life_sync = sync
            self._received.update(plan.cobs)
            stats.rx_frames += count
            stats.tpdos += count
            self._wake_if_complete()
        return True

    def _wake_if_complete(self) -> None:
        """Under the lock: wake a lockstep wait once every expected TPDO is in."""
        if self._expected is None or self._expected <= self._received:
            self._cv.notify_all()

    def _other_frame(self, can_id: int, data, timestamp: float) -> None:
        """A frame _receive_frames does not decode itself: the library's subscribers (heartbeat,
        EMCY, SDO, ...), a short TPDO (malformed), a TPDO coded entry by entry."""
        stats = self.stats
        stats.rx_frames += 1
        try:
            route = self._tpdo_in.get(can_id)
            if route is None:
                if can_id in self.network.subscribers:
                    self.network.notify(can_id, data, timestamp)
                else:
                    stats.unknown += 1
                return
            if len(data) < route.length:
                stats.malformed += 1
                return
            with self._lock:
                route.codec.decode_into(route.driver.values, data)
                route.health.life_sync = self._sync
                self._received.add(can_id)
                stats.tpdos += 1
                self._wake_if_complete()
        except Exception:
            stats.callback_errors += 1
            logger.exception("error handling frame 0x%03X", can_id)


class TpdoRoute:
    """Where a TPDO goes, fixed when the network is built from the drivers' layouts: its
    driver, the node's health and the compiled codec (devices.PdoCodec)."""

    __slots__ = ("driver", "health", "codec", "length", "keys", "unpack")

    def __init__(self, driver: DeviceDriver, health: NodeHealth, codec: PdoCodec):
        self.driver, self.health, self.codec = driver, health, codec
        self.length, self.keys = codec.length, codec.keys
        self.unpack = codec.struct.unpack_from if codec.struct is not None else None
