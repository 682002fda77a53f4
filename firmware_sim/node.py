"""A simulated CANopen slave: NMT, heartbeat producer and consumer, EMCY, node guarding,
object dictionary access for the device code, fault injection.

Built on canopen.LocalNode for the object dictionary (loaded from the EDS); fills the
library's gaps itself: boot-up message, NMT state handling (PDOs only in OPERATIONAL, no SDO
in STOPPED), a heartbeat producer driven by the simulator's timer thread, an EMCY producer
that maintains 1001h/1003h. Two parts live in their own modules and are the node's:
sdo_server (the SDO server with its stricter checks) and pdo_engine (RPDOs in, TPDOs out
on SYNC or event timer, the PDO mapping rules).

Frames reach a node from ``spacearm.firmware_sim.runner.Simulator``, which owns the bus.
"""
from __future__ import annotations

import struct
import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING

from canopen import objectdictionary as odlib
from canopen.sdo import SdoAbortedError

from spacearm.base.canopen import od
from spacearm.base.canopen.codes import ABORT_VALUE_INVALID
from spacearm.base.canopen.eds import load_od
from spacearm.firmware_sim.pdo_engine import Pdo, PdoEngine, is_pdo_config
from spacearm.firmware_sim.sdo_server import NodeTx, SdoServer, SimLocalNode, abort_frame

if TYPE_CHECKING:
    from spacearm.firmware_sim.plant import Plant

# the names this module had before the SDO server and the PDO engine left it (control.py, tests)
_NodeTx, _Pdo = NodeTx, Pdo
__all__ = ["Faults", "NodeStats", "ParamCache", "SimNode", "SimLocalNode"]


@dataclass
class Faults:
    """Fault injection switches of one node (tests flip these at any time)."""
    silent: bool = False            # node sends nothing and ignores the bus (power loss, bus-off)
    heartbeat_stopped: bool = False # heartbeat producer stops, node otherwise alive
    sdo_abort: int | None = None    # every SDO request is answered with this abort code
    drop_tx: int = 0                # drop this many of the next transmitted PDOs
    corrupt_tx: int = 0             # truncate this many of the next transmitted PDOs by one byte
    ignore_sync: bool = False       # TPDOs stop (node otherwise alive)
    frozen: bool = False            # sensor values stop updating, TPDOs go on (frozen sensor)
    ignore_quick_stop: bool = False # a joint drive stays in operation on a quick stop command


class ParamCache(dict):
    """param()'s cache. `epoch` moves whenever a cached value is dropped (a write to the object,
    a reset): what a device derives from cached settings holds while the epoch stands still."""
    epoch = 0

    def pop(self, key, *default):
        if key in self:
            self.epoch += 1
        return super().pop(key, *default)

    def __delitem__(self, key) -> None:
        self.epoch += 1
        super().__delitem__(key)

    def clear(self) -> None:
        self.epoch += 1
        super().clear()


@dataclass
class NodeStats:
    rx_frames: int = 0
    tx_frames: int = 0
    malformed: int = 0      # frames of a known service with a wrong length or contents
    sdo_aborts_sent: int = 0
    emcy_sent: int = 0
    dropped_tx: int = 0
    corrupted_tx: int = 0
    syncs: int = 0


class SimNode:
    """One independent simulated node (own node ID, OD, NMT state, SDO server, heartbeat)."""

    device_type = "generic"

    def __init__(self, node_id: int, eds_path, name: str = "", plant: "Plant | None" = None):
        self.node_id = node_id
        self.name = name or f"node{node_id}"
        self.plant = plant
        self.local = SimLocalNode(node_id, load_od(eds_path, node_id))
        self.od = self.local.object_dictionary
        # the library's NmtSlave would start its own heartbeat timer on 1017h writes; ours is
        # driven by the simulator (so it can be silenced)
        self.local._write_callbacks.remove(self.local.nmt.on_write)
        self.local.add_write_callback(self._on_od_write)
        self.faults = Faults()
        self.stats = NodeStats()
        self.nmt_state = od.NMT_STATE_BOOTUP
        self.powered = False
        self._send = None            # set by the simulator: send(can_id, data)
        self._lock = threading.RLock()
        self.pdo_engine = PdoEngine(self)
        self.sdo_server = SdoServer(self, self.local)
        self.sdo_session = self.sdo_server.session
        self.next_heartbeat = 0.0
        self.consumer_last: dict[int, float] = {}   # producer node ID -> last heartbeat (monotonic)
        self.consumer_excused: dict[int, float] = {}  # producer -> starvation excused from its silence
        self.pdo_changed_callback = None  # simulator: rebuild routing when RPDO COB-IDs change
        self._codecs: dict[tuple[int, int], tuple] = {}
        self._params = ParamCache()   # param() cache, dropped on writes to the object
        # consumer_entries(), what it read and the param() cache's epoch then
        self._consumer_entries: tuple[dict[int, float], dict, int] | None = None
        self.local.params_cache = self._params

    # ------------------------------------------------------------------ OD access
    def get(self, index: int, sub: int = 0):
        entry = self._codecs.get((index, sub))
        obj, codec, _ = entry if entry is not None else self._codec(index, sub)
        local = self.local
        data = None
        if not local._read_callbacks:     # raw()'s fast path, inline: a few objects every SYNC
            stored = local.data_store.get(index)
            if stored is not None:
                data = stored.get(sub)
        if data is None:
            data = local.get_data(index, sub)
        if codec is not None and len(data) == codec.size:
            return codec.unpack(data)[0]
        return obj.decode_raw(data)

    def raw(self, index: int, sub: int = 0) -> bytes:
        """The object's bytes as an SDO upload would return them."""
        # Fast path (hot every SYNC): a stored value, no read callbacks installed.
        if not self.local._read_callbacks:
            stored = self.local.data_store.get(index)
            if stored is not None:
                data = stored.get(sub)
                if data is not None:
                    return data
        return self.local.get_data(index, sub)

    def param(self, index: int, sub: int = 0):
        """get() for the device's settings (scaling, limits, ratings) read every SYNC: cached
        until any write reaches the object (SDO, RPDO or put) or the node resets."""
        key = (index, sub)
        cache = self._params
        value = cache.get(key)
        if value is None:
            value = cache[key] = self.get(index, sub)
        return value

    def put(self, index: int, sub: int, value) -> None:
        """Firmware-side write: no access checks, no callbacks (updates read-only values)."""
        if self._params:
            self._params.pop((index, sub), None)
        obj, codec, integer = self._codec(index, sub)
        if codec is None or isinstance(value, (bytes, bytearray)):
            data = obj.encode_raw(value)
        else:
            try:
                data = codec.pack(int(value) if integer else value)
            except struct.error:
                raise ValueError(f"0x{index:04X}:{sub:02X}: {value!r} does not fit {codec.format}") from None
        self.local.data_store.setdefault(index, {})[sub] = data

    def _codec(self, index: int, sub: int):
        """(object, struct of its number type or None, integer type?), cached: the device code
        reads and writes ~100 objects per SYNC and the OD never changes after loading."""
        entry = self._codecs.get((index, sub))
        if entry is None:
            obj = self.local._find_object(index, sub)
            entry = self._codecs[(index, sub)] = (obj, obj.STRUCT_TYPES.get(obj.data_type),
                                                  obj.data_type in odlib.INTEGER_TYPES)
        return entry

    # ------------------------------------------------------------------ lifecycle
    def power_on(self) -> None:
        self.powered = True
        self.reset(application=True)

    def reset(self, application: bool) -> None:
        """NMT reset node (application=True) or reset communication; ends with boot-up."""
        with self._lock:
            self.nmt_state = od.NMT_STATE_BOOTUP
            self._params.clear()
            self.store_generation += 1
            if application:
                self.local.data_store.clear()
                self.reset_application()
            else:
                for index in [i for i in self.local.data_store if 0x1000 <= i < 0x2000]:
                    if index not in (od.ERROR_REGISTER, od.PREDEFINED_ERROR_FIELD):
                        del self.local.data_store[index]
            self.pdo_engine.reset()
            self.consumer_last.clear()
            self._guard_toggle = 0
            self.send(od.HEARTBEAT_BASE + self.node_id, bytes([od.NMT_STATE_BOOTUP]))
            self.nmt_state = od.NMT_STATE_PRE_OPERATIONAL
            self.next_heartbeat = 0.0
        if self.pdo_changed_callback:
            self.pdo_changed_callback()

    def reset_application(self) -> None:
        """Device-specific: put the application objects back to power-on values."""

    def inject_fault(self, code: int = od.EMCY_GENERIC, register_bits: int = 0) -> None:
        """Fault injection: the device detects an error of this EMCY code (devices override)."""
        self.emcy(code, register_bits)

    # ------------------------------------------------------------------ transmit
    def send(self, can_id: int, data: bytes) -> None:
        if self.faults.silent or self._send is None or not self.powered:
            return
        self.stats.tx_frames += 1
        if can_id == od.SDO_TX_BASE + self.node_id and data[:1] == b"\x80":
            self.stats.sdo_aborts_sent += 1
            self.sdo_server.aborted()
        self._send(can_id, data)

    def send_frames(self, frames: list[tuple[int, bytes]]) -> None:
        """send() for each frame, in order, handed to the simulator at once (a SYNC's TPDOs;
        none on the SDO answer's COB-ID, whose aborts send() counts)."""
        if self.faults.silent or self._send is None or not self.powered:
            return
        if self._send_many is None:
            for can_id, data in frames:
                self._send(can_id, data)
        else:
            self._send_many(frames)
        self.stats.tx_frames += len(frames)

    _send_many = None   # set by the simulator: send_many([(can_id, data), ...])

    def heartbeat_period(self) -> float:
        # param(): every SYNC asks for every node (issue 35: decoding 1017h each time was a
        # fifth of the SYNC-time timers' CPU); a write drops the cached value (LocalNode.set_data)
        return self.param(od.PRODUCER_HEARTBEAT) / 1000.0

    def send_heartbeat(self) -> None:
        if not self.faults.heartbeat_stopped and self.nmt_state != od.NMT_STATE_BOOTUP:
            self.send(od.HEARTBEAT_BASE + self.node_id, bytes([self.nmt_state]))

    def on_guard_request(self) -> None:
        """Node guarding (CiA 301 7.2.8.3.2.1): answer the master's RTR with the NMT state and
        a toggle bit that alternates from 0 after each boot-up."""
        if od.GUARD_TIME not in self.od or self.faults.heartbeat_stopped or self.nmt_state == od.NMT_STATE_BOOTUP:
            return
        self.send(od.HEARTBEAT_BASE + self.node_id, bytes([self._guard_toggle | self.nmt_state]))
        self._guard_toggle ^= 0x80

    _guard_toggle = 0
    store_generation = 0    # counts the resets that empty (part of) the data store

    def emcy(self, code: int, register_bits: int = 0, info: bytes = b"") -> None:
        """Produce an EMCY; code 0 = error reset. Keeps 1001h and 1003h up to date."""
        with self._lock:
            if code == od.EMCY_NO_ERROR:
                register = 0
            else:
                register = self.get(od.ERROR_REGISTER) | od.ERR_REG_GENERIC | register_bits
                n = self.get(od.PREDEFINED_ERROR_FIELD, 0)
                history = [self.get(od.PREDEFINED_ERROR_FIELD, i) for i in range(1, 9)]
                history = [code] + history[:7]
                for i, value in enumerate(history, start=1):
                    self.put(od.PREDEFINED_ERROR_FIELD, i, value)
                self.put(od.PREDEFINED_ERROR_FIELD, 0, min(8, n + 1))
            self.put(od.ERROR_REGISTER, 0, register)
            cob = self.get(od.COB_ID_EMCY)
            if cob & od.PDO_COB_ID_INVALID or self.nmt_state == od.NMT_STATE_STOPPED:
                return
            self.stats.emcy_sent += 1
            self.send(cob & 0x7FF, struct.pack("<HB5s", code, register, info[:5]))

    # ------------------------------------------------------------------ receive
    def on_nmt(self, command: int) -> None:
        if command == od.NMT_START:
            self.nmt_state = od.NMT_STATE_OPERATIONAL
        elif command == od.NMT_STOP:
            self.nmt_state = od.NMT_STATE_STOPPED
        elif command == od.NMT_PRE_OPERATIONAL:
            self.nmt_state = od.NMT_STATE_PRE_OPERATIONAL
        elif command == od.NMT_RESET_NODE:
            self.reset(application=True)
        elif command == od.NMT_RESET_COMMUNICATION:
            self.reset(application=False)
        else:
            self.stats.malformed += 1

    def on_sdo_request(self, data: bytes) -> None:
        if self.nmt_state == od.NMT_STATE_STOPPED:
            return
        if len(data) != 8:
            self.stats.malformed += 1   # CiA 301: SDO frames have DLC 8; ignore others
            return
        if self.faults.sdo_abort is not None:
            _, index, sub = struct.unpack_from("<BHB", data)
            self.stats.sdo_aborts_sent += 1
            self.send(od.SDO_TX_BASE + self.node_id, abort_frame(index, sub, self.faults.sdo_abort))
            return
        self.sdo_server.request(data)

    def check_sdo_timeout(self, now: float) -> None:
        """Server-side SDO timeout: abort a transfer the client left unfinished."""
        self.sdo_server.check_timeout(now)

    # ------------------------------------------------------------------ PDOs (pdo_engine)
    # The node's entry points stay methods of the node: the simulator routes to them and a
    # redundant pair's line selection wraps them per node (line_selection._GATED).
    def on_rpdo(self, cob_id: int, data: bytes) -> None:
        self.pdo_engine.on_rpdo(cob_id, data)

    def rpdo_cob_ids(self) -> list[int]:
        return self.pdo_engine.rpdo_cob_ids()

    def send_tpdos(self) -> None:
        """Sample the mapped objects and send the synchronous TPDOs (OPERATIONAL only)."""
        self.pdo_engine.send_tpdos()

    @property
    def has_event_tpdos(self) -> bool:
        return self.pdo_engine.has_event_tpdos

    def send_event_tpdos(self, now: float) -> None:
        self.pdo_engine.send_event_tpdos(now)

    @property
    def _tpdos(self) -> list[Pdo] | None:
        return self.pdo_engine.tpdos

    @property
    def _rpdos(self) -> dict[int, Pdo] | None:
        return self.pdo_engine.rpdos

    # ------------------------------------------------------------------ heartbeat consumer
    def consumer_entries(self) -> dict[int, float]:
        """1016h: producer node ID -> timeout (s), for the active entries. Every consumed
        heartbeat and every timer pass asks, a write is rare: kept while the param() cache
        still holds the very values it was built from (a write or a reset drops them)."""
        cached, params = self._consumer_entries, self._params
        if cached is not None:
            if cached[2] == params.epoch:     # no cached value dropped since: the values it read stand
                return cached[0]
            if params.items() >= cached[1].items():
                self._consumer_entries = (cached[0], cached[1], params.epoch)
                return cached[0]
        out = {}
        read = {}
        if od.CONSUMER_HEARTBEAT in self.od:     # else a device without a heartbeat consumer
            count = read[(od.CONSUMER_HEARTBEAT, 0)] = self.param(od.CONSUMER_HEARTBEAT, 0)
            for sub in range(1, count + 1):
                value = read[(od.CONSUMER_HEARTBEAT, sub)] = self.param(od.CONSUMER_HEARTBEAT, sub)
                producer, ms = (value >> 16) & 0x7F, value & 0xFFFF
                if producer and ms:
                    out[producer] = ms / 1000.0
        self._consumer_entries = (out, read, self._params.epoch)
        return out

    def on_heartbeat(self, producer: int, now: float) -> None:
        # consumer_entries()'s usual answer inline: every node takes every master heartbeat,
        # five times as often on a redundant pair (issue 34)
        cached = self._consumer_entries
        entries = cached[0] if cached is not None and cached[2] == self._params.epoch else self.consumer_entries()
        if producer in entries:
            self.consumer_last[producer] = now    # monitoring starts with the first heartbeat
            self.consumer_excused.pop(producer, None)

    def excuse_consumers(self, starved: float) -> None:
        """The simulator could not observe the bus for `starved` s (its process was starved):
        not silence of the consumed heartbeats, up to half of each one's timeout per silence."""
        entries = self.consumer_entries()
        for producer in list(self.consumer_last):
            used = self.consumer_excused.get(producer, 0.0)
            grant = min(starved, 0.5 * entries.get(producer, 0.0) - used)
            if grant > 0.0:
                self.consumer_last[producer] += grant
                self.consumer_excused[producer] = used + grant

    def check_consumers(self, now: float) -> None:
        if not self.consumer_last:
            return
        # consumer_entries()'s usual answer inline: on the SYNC time base every node, every SYNC
        cached = self._consumer_entries
        entries = cached[0] if cached is not None and cached[2] == self._params.epoch else self.consumer_entries()
        for producer, last in list(self.consumer_last.items()):
            timeout = entries.get(producer)
            if timeout is None:
                del self.consumer_last[producer]
            elif now - last > timeout:
                del self.consumer_last[producer]        # re-armed by the next heartbeat
                self.consumer_timed_out(producer, now)

    def consumer_timed_out(self, producer: int, now: float) -> None:
        """A consumed heartbeat timed out: EMCY 8130h, then the device's reaction. On a redundant
        pair the line selection answers the master's own (firmware_sim/line_selection.py)."""
        self.emcy(od.EMCY_HEARTBEAT_ERROR, od.ERR_REG_COMMUNICATION, bytes([producer]))
        self.on_heartbeat_lost(producer)

    def on_heartbeat_lost(self, producer: int) -> None:
        """Device specific reaction to a consumer heartbeat timeout (after the EMCY)."""

    def sync_cob_id(self) -> int:
        return self.get(od.COB_ID_SYNC) & 0x7FF

    # ------------------------------------------------------------------ SYNC hooks
    def on_sync_begin(self, dt: float) -> None:
        """Latch the commands received since the last SYNC (device specific)."""

    def on_sync_end(self, dt: float) -> None:
        """Update the OD from the plant after the physics step (device specific)."""

    # ------------------------------------------------------------------ OD write rules
    def _on_od_write(self, index, subindex, od, data, **_):  # noqa: A002 - library keyword
        self._params.pop((index, subindex), None)
        from spacearm.base.canopen import od as ids
        self.pdo_engine.check_config_write(index, subindex, data)
        if is_pdo_config(index) and self.pdo_changed_callback:
            # after the store: defer via flag (the value is stored after callbacks run)
            self._routing_dirty = True
        if index == ids.PREDEFINED_ERROR_FIELD and subindex == 0:
            if int.from_bytes(bytes(data), "little") != 0:
                raise SdoAbortedError(ABORT_VALUE_INVALID)  # CiA 301: only 0 may be written (clears history)
            for i in range(1, 9):
                self.put(ids.PREDEFINED_ERROR_FIELD, i, 0)
        if index == ids.COB_ID_SYNC:
            self._routing_dirty = True
        self.on_write(index, subindex, bytes(data))

    _routing_dirty = False
    in_rpdo = False   # True while an RPDO (not an SDO) is writing the OD

    # The application objects (2000h and up) this class's on_write reacts to; an RPDO skips
    # the call for the others (issue 35: most mapped objects are plain set-points). None: any.
    WRITE_REACTIONS: frozenset[int] | None = frozenset()

    def write_reactions(self) -> frozenset[int] | None:
        """WRITE_REACTIONS as declared beside the on_write in use: a subclass that overrides
        on_write without declaring its own reacts to every object."""
        for cls in type(self).__mro__:
            if "on_write" in cls.__dict__:
                return cls.__dict__.get("WRITE_REACTIONS")
        return None

    def pure_write_check(self):
        """The on_write function in use when its class declares it a pure check (PURE_WRITE_CHECK:
        it changes nothing and the same arguments always pass or always raise), else None: the
        compiled core then skips the call for a chunk it let pass before (_simcore.c store_rpdo)."""
        for cls in type(self).__mro__:
            if "on_write" in cls.__dict__:
                return cls.__dict__["on_write"] if cls.__dict__.get("PURE_WRITE_CHECK") else None
        return None

    def on_write(self, index: int, subindex: int, data: bytes) -> None:
        """Device specific reaction to an SDO/RPDO write (called before the value is stored)."""
