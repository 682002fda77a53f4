"""The laser ranger's serial protocol, shared by the driver (drivers/laser_ranger.py) and the
simulated ranger (firmware_sim/laser_ranger.py).

Protocol (ASCII lines, NMEA-style checksum), 115200 8N1 nominal:

    frame    = "$" body "*" CS "\\r\\n"
    CS       = two upper-case hex digits, XOR of every byte of body
    requests = MEAS | INFO | PING
    replies  = D,<distance mm, 3 decimals>      valid reading
               E,NOHIT                          beam misses the target or out of range
               I,<model>,<min mm>,<max mm>,<sigma mm>
               P,OK
               E,BADCS | E,UNKNOWN | E,FORMAT   request rejected
"""
from __future__ import annotations

from typing import Optional


def checksum(body: bytes) -> int:
    cs = 0
    for b in body:
        cs ^= b
    return cs


def frame(body: str) -> bytes:
    raw = body.encode("ascii")
    return b"$" + raw + b"*" + f"{checksum(raw):02X}".encode() + b"\r\n"


def parse_frame(line: bytes) -> Optional[str]:
    """Body of a well-formed frame with a correct checksum, else None."""
    line = line.strip()
    if len(line) < 4 or not line.startswith(b"$") or line[-3:-2] != b"*":
        return None
    body, cs = line[1:-3], line[-2:]
    try:
        if int(cs, 16) != checksum(body):
            return None
        return body.decode("ascii")
    except (ValueError, UnicodeDecodeError):
        return None
