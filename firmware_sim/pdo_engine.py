"""A simulated node's PDO engine: the PDO tables read from the object dictionary, RPDOs
written into it, TPDOs sampled from it on SYNC or by their event timer (CiA 301 7.2.2).

The tables are read once per configuration (the communication and mapping objects; a write
to either drops them) and each RPDO's decoder is compiled on first use, so a frame costs a
few slices and dict stores, not an object dictionary lookup per mapped object.

The engine works on its node's object dictionary through the node (node.SimNode): its NMT
state, fault switches, statistics, lock and send(); it imports nothing of the node's module.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from operator import getitem

from canopen import objectdictionary as odlib
from canopen.sdo import SdoAbortedError

from spacearm.base.canopen import od
from spacearm.base.canopen.codes import ABORT_DEVICE_STATE, ABORT_NOT_MAPPABLE, ABORT_PDO_LENGTH
from spacearm.firmware_sim import simcore


@dataclass
class Pdo:
    cob_id: int
    transmission_type: int
    entries: list[tuple[int, int, int]] = field(default_factory=list)  # (index, sub, bytes)
    event_timer: float = 0.0     # s (1800h.5); event-driven TPDOs (254/255) are sent at this period
    next_event: float = 0.0      # monotonic time of the next event-timer transmission
    codec: tuple | None = None   # RPDO: decoder compiled on first use (PdoEngine._compile_rpdo)
    slots: tuple | None = None   # TPDO: (store generation, dicts, subindices) (PdoEngine._slots)

    @property
    def length(self) -> int:
        return sum(e[2] for e in self.entries)


def is_pdo_config(index: int) -> bool:
    """A communication or mapping object of an RPDO or TPDO (1400h-1BFFh)."""
    return od.RPDO_COMM <= index < od.TPDO_MAP + od.N_PDOS


class PdoEngine:
    def __init__(self, node):
        self.node = node
        self.tpdos: list[Pdo] | None = None
        self.rpdos: dict[int, Pdo] | None = None
        self.sync_counter = 0

    def invalidate(self) -> None:
        """The PDO configuration changed (or the node reset): read the tables again."""
        self.tpdos = self.rpdos = None

    def reset(self) -> None:
        self.invalidate()
        self.sync_counter = 0

    # ------------------------------------------------------------------ receive
    def rpdo_cob_ids(self) -> list[int]:
        if self.rpdos is None:
            self.rpdos = {pdo.cob_id: pdo for pdo in self._read_pdos(od.RPDO_COMM, od.RPDO_MAP)}
        return list(self.rpdos)

    def on_rpdo(self, cob_id: int, data: bytes) -> None:
        node = self.node
        if node.nmt_state != od.NMT_STATE_OPERATIONAL:
            return
        pdo = (self.rpdos or {}).get(cob_id)
        if pdo is None:
            return
        codec = pdo.codec
        if codec is None:
            codec = pdo.codec = self._compile_rpdo(pdo)
        if codec and len(data) < codec[-1][3]:    # the last entry's end: the mapped length
            node.stats.malformed += 1
            node.emcy(od.EMCY_PDO_LENGTH, od.ERR_REG_COMMUNICATION)
            return
        local = node.local
        store = local.data_store
        callbacks = local._write_callbacks
        write_rules = node._on_od_write
        generic = len(callbacks) != 1 or callbacks[0] != write_rules
        on_write = node.on_write
        params = node._params
        core = simcore.core
        with node._lock:
            node.in_rpdo = True
            try:
                if core is not None and not generic:
                    core.rpdo_store(codec, data, store, params, on_write, write_rules, SdoAbortedError, node.stats)
                    return
                for index, sub, start, end, obj, size_ok, key, reacts in codec:
                    chunk = data[start:end]
                    if not size_ok:          # mapped size differs from the object's type
                        node.stats.malformed += 1
                        continue
                    try:
                        if generic:
                            for callback in callbacks:
                                callback(index=index, subindex=sub, od=obj, data=chunk)
                        elif index < 0x2000:   # communication area: the full write rules
                            write_rules(index, sub, obj, chunk)
                        elif reacts:           # application objects: only the device's reaction
                            on_write(index, sub, chunk)
                    except SdoAbortedError:
                        node.stats.malformed += 1
                        continue
                    entry = store.get(index)
                    if entry is None:
                        entry = store[index] = {}
                    entry[sub] = chunk
                    if params and key in params:
                        del params[key]
            finally:
                node.in_rpdo = False

    def _compile_rpdo(self, pdo: Pdo) -> tuple:
        """The RPDO's decoder, built once per mapping: per entry its byte slice, the object and
        whether the mapped length fits the object's type (what LocalNode.set_data checks per
        frame), its param() cache key, and whether the device reacts to a write of it (its
        on_write is called only then: SimNode.write_reactions). Unknown objects are left out
        (set_data would abort: counted as malformed)."""
        out, offset = [], 0
        reactions = self.node.write_reactions()
        for index, sub, size in pdo.entries:
            try:
                obj = self.node.local._find_object(index, sub)
            except SdoAbortedError:
                obj = None
            reacts = reactions is None or index in reactions
            if obj is not None:
                size_ok = obj.data_type not in odlib.NUMBER_TYPES or 8 * size == len(obj)
                out.append((index, sub, offset, offset + size, obj, size_ok, (index, sub), reacts))
            else:
                out.append((index, sub, offset, offset + size, None, False, (index, sub), reacts))
            offset += size
        return tuple(out)

    # ------------------------------------------------------------------ transmit
    def send_tpdos(self) -> None:
        """Sample the mapped objects and send the synchronous TPDOs (OPERATIONAL only)."""
        node = self.node
        self.sync_counter += 1
        node.stats.syncs += 1
        if node.nmt_state != od.NMT_STATE_OPERATIONAL or node.faults.ignore_sync:
            return
        tpdos = self.tpdos
        if tpdos is None:
            tpdos = self._tpdo_table()
        counter = self.sync_counter
        core, faults = simcore.core, node.faults
        if core is not None and self._plain_cobs and not faults.drop_tx and not faults.corrupt_tx \
                and not node.local._read_callbacks:
            key = self._core_key       # _core_table's usual answer inline: every node, every SYNC
            table = self._core_rows if key is not None and key[0] is tpdos and key[1] == node.store_generation \
                else self._core_table(tpdos)
            if table is not None:
                with node._lock:
                    frames = core.tpdo_frames(table, counter)
                if frames is not None:
                    if frames:
                        node.send_frames(frames)
                    return
        due = [pdo for pdo in tpdos
               if 0 <= pdo.transmission_type <= 240 and not (pdo.transmission_type > 1 and counter % pdo.transmission_type)]
        if due:
            # one lock and one hand-over to the simulator for the SYNC's frames (issue 35)
            frames = [frame for frame in map(self._frame, self._sample(due)) if frame is not None]
            if self._plain_cobs:
                node.send_frames(frames)
            else:                        # a TPDO on the SDO answer's COB-ID: send() counts its aborts
                for frame in frames:
                    node.send(*frame)

    _core_key: tuple | None = None
    _core_rows: tuple | None = None

    def _core_table(self, tpdos: list[Pdo]) -> tuple | None:
        """The compiled core's view of the TPDOs (cob_id, transmission type, _slots()), kept while
        the table and the data store last; None while a mapped object is not stored yet."""
        key = (tpdos, self.node.store_generation)
        if self._core_key is None or self._core_key[0] is not tpdos or self._core_key[1] != key[1]:
            try:
                self._core_rows = tuple((pdo.cob_id, pdo.transmission_type, *self._slots(pdo)) for pdo in tpdos)
            except KeyError:
                return None
            self._core_key = key
        return self._core_rows

    def _tpdo_table(self) -> list[Pdo]:
        if self.tpdos is None:
            self.tpdos = self._read_pdos(od.TPDO_COMM, od.TPDO_MAP)
            self._plain_cobs = all(pdo.cob_id != od.SDO_TX_BASE + self.node.node_id for pdo in self.tpdos)
        return self.tpdos

    _plain_cobs = True

    @property
    def has_event_tpdos(self) -> bool:
        """Cheap check for the timer thread: any event-timer TPDO (or not known yet)?"""
        if self.node.nmt_state != od.NMT_STATE_OPERATIONAL:
            return False
        tpdos = self.tpdos
        return tpdos is None or any(p.transmission_type >= 254 and p.event_timer > 0 for p in tpdos)

    def send_event_tpdos(self, now: float) -> None:
        """Event-driven TPDOs (transmission type 254/255) with an event timer: sent every
        event-timer period while OPERATIONAL (the simulator's timer thread calls this)."""
        node = self.node
        if node.nmt_state != od.NMT_STATE_OPERATIONAL or node.faults.ignore_sync:
            return
        for pdo in self._tpdo_table():
            if pdo.transmission_type < 254 or pdo.event_timer <= 0.0:
                continue
            if pdo.next_event == 0.0:
                pdo.next_event = now + pdo.event_timer
            elif now >= pdo.next_event:
                pdo.next_event = max(pdo.next_event + pdo.event_timer, now)
                self._transmit(pdo)

    def _transmit(self, pdo: Pdo) -> None:
        frame = self._frame(self._sample((pdo,))[0])
        if frame is not None:
            self.node.send(*frame)

    def _sample(self, pdos) -> list[tuple[int, bytes]]:
        """(COB-ID, the mapped objects' bytes) of each PDO, under the node's lock."""
        node = self.node
        with node._lock:
            if not node.local._read_callbacks:
                try:     # hot path: every entry is a stored value and no read callback is installed
                    return [(pdo.cob_id, b"".join(map(getitem, *self._slots(pdo)))) for pdo in pdos]
                except KeyError:
                    pass
            raw = node.raw
            return [(pdo.cob_id, b"".join([raw(index, sub) for index, sub, _ in pdo.entries])) for pdo in pdos]

    def _slots(self, pdo: Pdo) -> tuple[tuple[dict, ...], tuple[int, ...]]:
        """The data store's dict of each mapped object's index and its subindex: compiled once
        per mapping (a new mapping is a new Pdo) and kept until a reset empties the store, so
        a TPDO is sampled without a Python frame per entry. KeyError: not every object stored."""
        generation = self.node.store_generation
        slots = pdo.slots
        if slots is None or slots[0] != generation:
            store = self.node.local.data_store
            slots = pdo.slots = (generation, tuple(store[index] for index, _, _ in pdo.entries),
                                 tuple(sub for _, sub, _ in pdo.entries))
        return slots[1], slots[2]

    def _frame(self, frame: tuple[int, bytes]) -> tuple[int, bytes] | None:
        """The frame as the fault switches let it out: dropped (None) or one byte short."""
        faults = self.node.faults
        if faults.drop_tx > 0:
            faults.drop_tx -= 1
            self.node.stats.dropped_tx += 1
            return None
        if faults.corrupt_tx > 0 and frame[1]:
            faults.corrupt_tx -= 1
            self.node.stats.corrupted_tx += 1
            return frame[0], frame[1][:-1]
        return frame

    def _read_pdos(self, comm_base: int, map_base: int) -> list[Pdo]:
        get, dictionary = self.node.get, self.node.od
        pdos = []
        for n in range(od.N_PDOS):
            if comm_base + n not in dictionary:     # the device has fewer PDOs
                break
            cob = get(comm_base + n, od.PDO_COB_ID)
            if cob & od.PDO_COB_ID_INVALID:
                continue
            entries = []
            for i in range(1, get(map_base + n, 0) + 1):
                value = get(map_base + n, i)
                entries.append((value >> 16, (value >> 8) & 0xFF, (value & 0xFF) // 8))
            timer = 0.0
            if comm_base == od.TPDO_COMM and od.PDO_EVENT_TIMER in dictionary[comm_base + n]:
                timer = get(comm_base + n, od.PDO_EVENT_TIMER) / 1000.0
            pdos.append(Pdo(cob & 0x7FF, get(comm_base + n, od.PDO_TRANSMISSION_TYPE), entries, timer))
        return pdos

    # ------------------------------------------------------------------ write rules
    def check_config_write(self, index: int, subindex: int, data) -> None:
        """CiA 301's rules for a write to a mapping object (raises the SDO abort): a mapping
        changes only while its PDO is disabled, maps only mappable objects of the right
        length and direction, and fits 64 bits. Then the tables are read again."""
        if od.RPDO_MAP <= index < od.RPDO_MAP + od.N_PDOS or od.TPDO_MAP <= index < od.TPDO_MAP + od.N_PDOS:
            node = self.node
            comm = (od.RPDO_COMM if index < od.TPDO_MAP else od.TPDO_COMM) + (index & 0xFF)
            if not node.get(comm, od.PDO_COB_ID) & od.PDO_COB_ID_INVALID:
                raise SdoAbortedError(ABORT_DEVICE_STATE)   # change mapping only while the PDO is disabled
            value = int.from_bytes(bytes(data), "little")
            if subindex == 0:
                total = sum(node.get(index, i) & 0xFF for i in range(1, value + 1))
                if total > 64:
                    raise SdoAbortedError(ABORT_PDO_LENGTH)
            elif value != 0:
                m_index, m_sub, bits = value >> 16, (value >> 8) & 0xFF, value & 0xFF
                try:
                    target = node.local._find_object(m_index, m_sub)
                except SdoAbortedError:
                    raise SdoAbortedError(ABORT_NOT_MAPPABLE) from None
                if not target.pdo_mappable or bits != len(target):
                    raise SdoAbortedError(ABORT_NOT_MAPPABLE)
                rx = index < od.TPDO_MAP
                if rx and not target.writable or not rx and not target.readable:
                    raise SdoAbortedError(ABORT_NOT_MAPPABLE)
        if is_pdo_config(index):
            self.invalidate()
