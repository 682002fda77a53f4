"""Wire format shared by the loopback hub and its clients.

Every record on the TCP stream is length-prefixed:

    u8 length | u8 type | body (length - 1 bytes)

type FRAME (1):  u8 flags | u32 arbitration id (big endian) | u8 dlc | data (0..64 bytes)
type HELLO (2):  client -> hub: 8-byte magic | u8 version | u8 options | channel name (utf-8)
type WELCOME (3): hub -> client: 8-byte magic | u8 version | u32 client id

A record is at most 256 bytes, so a reader never needs more than one small buffer, and a
corrupted stream is detected at once (unknown type, bad length) instead of desynchronising.
"""
from __future__ import annotations

import struct

import can

MAGIC = b"SPCARMHB"
VERSION = 1

T_FRAME = 1
T_HELLO = 2
T_WELCOME = 3

OPT_RECEIVE_OWN = 0x01
OPT_HUB_REPORTS = 0x02    # the client wants the hub's own timing reports (base/canopen/peer_timing.py)

F_EXTENDED = 0x01
F_REMOTE = 0x02
F_ERROR = 0x04
F_FD = 0x08
F_BRS = 0x10
F_ESI = 0x20
_KNOWN_FLAGS = F_EXTENDED | F_REMOTE | F_ERROR | F_FD | F_BRS | F_ESI

_FRAME_HDR = struct.Struct("!BBBIB")  # length, type, flags, arbitration id, dlc
FRAME_HDR_LEN = _FRAME_HDR.size - 1  # bytes counted by the length field (everything after it)
MAX_CHANNEL_NAME = 200
_FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)


class ProtocolError(Exception):
    """The byte stream is not a valid hub stream (wrong peer, corruption or version mismatch)."""


def encode_frame(msg: can.Message) -> bytes:
    data = bytes(msg.data or b"")
    flags = 0
    if msg.is_extended_id:
        flags |= F_EXTENDED
    if msg.is_remote_frame:
        flags |= F_REMOTE
    if msg.is_error_frame:
        flags |= F_ERROR
    if msg.is_fd:
        flags |= F_FD
    if msg.bitrate_switch:
        flags |= F_BRS
    if msg.error_state_indicator:
        flags |= F_ESI
    limit = 64 if msg.is_fd else 8
    if len(data) > limit:
        raise ValueError(f"CAN{' FD' if msg.is_fd else ''} frame carries at most {limit} bytes, got {len(data)}")
    max_id = 0x1FFFFFFF if msg.is_extended_id else 0x7FF
    if not 0 <= msg.arbitration_id <= max_id:
        raise ValueError(f"arbitration id 0x{msg.arbitration_id:X} out of range for "
                         f"{'extended' if msg.is_extended_id else 'standard'} frame")
    dlc = msg.dlc if msg.dlc is not None else len(data)
    if not 0 <= dlc <= 64:
        raise ValueError(f"bad dlc {dlc}")
    return _FRAME_HDR.pack(FRAME_HDR_LEN + len(data), T_FRAME, flags, msg.arbitration_id, dlc) + data


def encode_data_frame(can_id: int, data: bytes) -> bytes:
    """The FRAME record of a standard-ID data frame given as plain values (the hot path: no
    can.Message). Raises ValueError for what no classic CAN controller could send."""
    if not 0 <= can_id <= 0x7FF or len(data) > 8:
        raise ValueError(f"frame 0x{can_id:X} with {len(data)} bytes is not a standard CAN data frame")
    return _FRAME_HDR.pack(FRAME_HDR_LEN + len(data), T_FRAME, 0, can_id, len(data)) + data


def encode_data_frames(frames) -> bytes:
    """The FRAME records of standard-ID data frames [(can_id, data), ...] as one stream: what
    encode_data_frame gives each, joined, without a call per frame (a cycle's RPDO burst on
    the loopback bus). Raises encode_data_frame's ValueError for the first frame it refuses."""
    header, size, kind = _FRAME_HDR.pack, FRAME_HDR_LEN, T_FRAME
    parts = []
    append = parts.append
    for can_id, data in frames:
        n = len(data)
        if not 0 <= can_id <= 0x7FF or n > 8:
            encode_data_frame(can_id, data)     # its error, word for word
        append(header(size + n, kind, 0, can_id, n))
        append(data)
    return b"".join(parts)


def check_frame_body(body: bytes | memoryview) -> None:
    """Validate a FRAME body (the bytes after the type byte); raise ProtocolError if malformed."""
    if len(body) < 6:
        raise ProtocolError(f"frame record too short ({len(body)} bytes)")
    flags = body[0]
    if flags & ~_KNOWN_FLAGS:
        raise ProtocolError(f"unknown frame flags 0x{flags:02X}")
    ndata = len(body) - 6
    if ndata > (64 if flags & F_FD else 8):
        raise ProtocolError(f"frame carries {ndata} data bytes")


def decode_frame(body: bytes | memoryview, timestamp: float, channel: str | None) -> can.Message:
    check_frame_body(body)
    flags = body[0]
    arb_id = int.from_bytes(body[1:5], "big")
    dlc = body[5]
    data = bytes(body[6:])
    return can.Message(
        timestamp=timestamp,
        arbitration_id=arb_id,
        is_extended_id=bool(flags & F_EXTENDED),
        is_remote_frame=bool(flags & F_REMOTE),
        is_error_frame=bool(flags & F_ERROR),
        is_fd=bool(flags & F_FD),
        bitrate_switch=bool(flags & F_BRS),
        error_state_indicator=bool(flags & F_ESI),
        dlc=dlc,
        data=data,
        channel=channel,
        check=False,
    )


_Message = can.Message


def frames_end(buf: bytearray) -> tuple[int, int]:
    """(bytes, count) of the complete, well-formed FRAME records at the start of buf, checked
    in place (the hub forwards them as one slice); ProtocolError on anything else."""
    pos = count = 0
    n = len(buf)
    while pos < n:
        length = buf[pos]
        end = pos + 1 + length
        if end > n:
            break
        if length < 7 or buf[pos + 1] != T_FRAME:
            raise ProtocolError(f"unexpected record (type {buf[pos + 1] if length else None}, length {length})")
        flags = buf[pos + 2]
        if flags & ~_KNOWN_FLAGS or length - 7 > (64 if flags & F_FD else 8):
            raise ProtocolError(f"malformed frame record (flags 0x{flags:02X}, {length - 7} data bytes)")
        pos = end
        count += 1
    return pos, count


def decode_stream(buf: bytearray, timestamp: float, channel: str | None, plain=None) -> list[can.Message]:
    """Decode every complete FRAME record at the start of buf (removing them).
    With `plain`, the standard-ID data frames (no flags) are handed to plain([(can_id, data),
    ...], timestamp) in one call, in order, instead of becoming can.Messages; the list holds
    only the other frames. Raises ProtocolError (and removes nothing) if any record is not a
    well-formed FRAME."""
    stop, _ = frames_end(buf)
    out = []
    burst = []
    pos = 0
    while pos < stop:
        end = pos + 1 + buf[pos]
        flags = buf[pos + 2]
        can_id = int.from_bytes(buf[pos + 3:pos + 7], "big")
        if plain is not None and not flags:
            burst.append((can_id, bytes(buf[pos + 8:end])))
        else:
            out.append(_Message(
                timestamp=timestamp, arbitration_id=can_id,
                is_extended_id=bool(flags & F_EXTENDED), is_remote_frame=bool(flags & F_REMOTE),
                is_error_frame=bool(flags & F_ERROR), is_fd=bool(flags & F_FD),
                bitrate_switch=bool(flags & F_BRS), error_state_indicator=bool(flags & F_ESI),
                dlc=buf[pos + 7], data=bytes(buf[pos + 8:end]), channel=channel))
        pos = end
    if stop:
        del buf[:stop]
    if burst:
        plain(burst, timestamp)
    return out


def encode_hello(channel: str, receive_own: bool, hub_reports: bool = False) -> bytes:
    name = channel.encode("utf-8")
    if not name or len(name) > MAX_CHANNEL_NAME:
        raise ValueError(f"loopback channel name must be 1..{MAX_CHANNEL_NAME} bytes")
    body = bytes([T_HELLO]) + MAGIC + bytes([VERSION, (OPT_RECEIVE_OWN if receive_own else 0)
                                                  | (OPT_HUB_REPORTS if hub_reports else 0)]) + name
    return bytes([len(body)]) + body


def encode_welcome(client_id: int) -> bytes:
    body = bytes([T_WELCOME]) + MAGIC + bytes([VERSION]) + struct.pack("!I", client_id & 0xFFFFFFFF)
    return bytes([len(body)]) + body


def split_records(buf: bytearray):
    """Yield (type, body) for every complete record at the start of buf and remove them."""
    pos = 0
    n = len(buf)
    out = []
    while pos < n:
        length = buf[pos]
        if length == 0:
            raise ProtocolError("zero-length record")
        end = pos + 1 + length
        if end > n:
            break
        out.append((buf[pos + 1], bytes(buf[pos + 2:end])))
        pos = end
    if pos:
        del buf[:pos]
    return out
