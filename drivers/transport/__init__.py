"""One factory for CAN buses, named by a string (as python-can does with interfaces).

    virtual:NAME       python-can's in-process virtual bus (the embedded default)
    socketcan:CHANNEL  Linux SocketCAN (vcan0 in tests, can0 on hardware)
"""
from __future__ import annotations

import can


class BusSpecError(ValueError):
    """The --bus string does not name a known transport."""


def open_bus(spec: str, **kwargs) -> can.BusABC:
    kind, sep, rest = spec.partition(":")
    if not sep or not rest:
        raise BusSpecError(f"bus '{spec}': expected KIND:NAME, e.g. virtual:arm or socketcan:vcan0")
    if kind == "virtual":
        # receive_own_messages=False: like a real controller, a node does not see its own frames.
        return can.Bus(interface="virtual", channel=rest, **kwargs)
    if kind == "socketcan":
        return can.Bus(interface="socketcan", channel=rest, **kwargs)
    raise BusSpecError(f"bus '{spec}': unknown transport '{kind}' (known: virtual, socketcan)")
