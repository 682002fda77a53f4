"""A simulated node's SDO server: canopen's LocalNode and SdoServer with the checks a
conformant server makes that the library leaves out.

- SimLocalNode: on download, the length must match a number object's type and the value
  its 1000h-range limits (aborts 0607 0012/0013, 0609 0031/0032); found objects are cached;
- SdoServer: requests screened by the transfer state (sdo_session.SdoSession: aborts, stray
  segments, block uploads, the server-side timeout) before the library answers.

A node owns one SdoServer; the node's NMT state and fault switches decide whether a request
reaches it (node.SimNode.on_sdo_request).
"""
from __future__ import annotations

import struct
import time

import canopen
from canopen import objectdictionary as odlib
from canopen.sdo import SdoAbortedError

from spacearm.base.canopen import od
from spacearm.base.canopen.codes import ABORT_LENGTH_HIGH, ABORT_LENGTH_LOW, ABORT_READ_ONLY, ABORT_VALUE_HIGH, \
    ABORT_VALUE_LOW
from spacearm.firmware_sim.sdo_session import SdoSession

# the client command specifiers (CiA 301) of a segment: the request does not name its object
_SEGMENT_CCS = (0x00, 0x60)
# those that open a transfer: whatever the last one left in the library's buffer is stale
_NEW_TRANSFER_CCS = (0x20, 0x40, 0xA0)


class SimLocalNode(canopen.LocalNode):
    """LocalNode with the checks a conformant SDO server makes on download."""

    def _find_object(self, index, subindex):
        # Every SYNC reads and writes ~100 objects per node; the library's lookup walks the
        # OD each time. The OD never changes after loading, so found objects are cached
        # (misses still raise the library's SDO abort).
        cache = self.__dict__.setdefault("_object_cache", {})
        obj = cache.get((index, subindex))
        if obj is None:
            obj = cache[(index, subindex)] = super()._find_object(index, subindex)
        return obj

    def set_data(self, index, subindex, data, check_writable=False):
        obj = self._find_object(index, subindex)
        if check_writable and not obj.writable:
            raise SdoAbortedError(ABORT_READ_ONLY)
        if obj.data_type in odlib.NUMBER_TYPES:
            size = len(obj) // 8
            if len(data) > size:
                raise SdoAbortedError(ABORT_LENGTH_HIGH)
            if len(data) < size:
                raise SdoAbortedError(ABORT_LENGTH_LOW)
            if check_writable:
                value = obj.decode_raw(bytes(data))
                if obj.max is not None and value > obj.max:
                    raise SdoAbortedError(ABORT_VALUE_HIGH)
                if obj.min is not None and value < obj.min:
                    raise SdoAbortedError(ABORT_VALUE_LOW)
        super().set_data(index, subindex, data, check_writable)
        params = self.__dict__.get("params_cache")
        if params:                 # SimNode.param(): the stored value changed
            params.pop((index, subindex), None)


class NodeTx:
    """What the library's SdoServer sees as its network: sends through the node."""

    def __init__(self, node):
        self.node = node

    def send_message(self, can_id, data, remote=False):
        self.node.send(can_id, bytes(data))


def name_the_object(sdo, data: bytes) -> None:
    """canopen's SdoServer.abort() answers with the object of the transfer and fails on the
    first request otherwise: a request that names its object (any but a segment) sets it."""
    if data[0] & 0xE0 not in _SEGMENT_CCS or sdo._index is None:
        _, sdo._index, sdo._subindex = struct.unpack_from("<BHB", data)


def abort_frame(index: int, sub: int, code: int) -> bytes:
    return struct.pack("<BHBL", 0x80, index, sub, code)


class SdoServer:
    """One node's SDO server: screens each request, lets the library answer, aborts a
    transfer left unfinished. Sends through node.send (which counts the aborts)."""

    def __init__(self, node, local: SimLocalNode):
        self.node = node
        self.local = local
        self.session = SdoSession()
        self._tx_cob = od.SDO_TX_BASE + node.node_id
        self._rx_cob = od.SDO_RX_BASE + node.node_id
        local.sdo.network = NodeTx(node)

    def request(self, data: bytes) -> None:
        """An 8-byte request to this server."""
        sdo = self.local.sdo
        session = self.session
        go, abort = session.screen(data, time.monotonic(), self._object_size)
        if abort is not None:
            self.abort(session.index, session.sub, abort)
        if not go:
            sdo._buffer = None
            return
        if data[0] & 0xE0 in _NEW_TRANSFER_CCS:
            sdo._buffer = None      # a new transfer: nothing left over from the last one
        name_the_object(sdo, data)
        with self.node._lock:
            sdo.on_request(self._rx_cob, bytearray(data), 0.0)
            session.after(data, bool(sdo._buffer))

    def abort(self, index: int, sub: int, code: int) -> None:
        self.node.send(self._tx_cob, abort_frame(index, sub, code))

    def aborted(self) -> None:
        """An abort went out (ours or the library's): the transfer is over, no stale segments."""
        self.session.aborted()
        self.local.sdo._buffer = None

    def check_timeout(self, now: float) -> None:
        """Server-side SDO timeout: abort a transfer the client left unfinished."""
        expired = self.session.expired(now)
        if expired is not None:
            self.local.sdo._buffer = None
            self.abort(*expired)

    def _object_size(self, index: int, sub: int) -> int | None:
        try:
            return len(self.node.raw(index, sub))
        except Exception:   # absent object: the library answers the request itself
            return None
