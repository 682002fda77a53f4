"""Line faults in the loopback hub (the hub is the line: a fault there is every client's):
injected by call and by the hub's fault file, judged by what a plain client receives."""
from __future__ import annotations

import time

import can

from spacearm.base.transport import open_bus
from spacearm.base.transport.hub import LoopbackHub
from spacearm.base.transport.line_faults import BABBLE_ID


def received(bus, wait=0.3):
    out, end = [], time.monotonic() + wait
    while time.monotonic() < end:
        msg = bus.recv(0.02)
        if msg is not None:
            out.append(msg)
    return out


def test_hub_cut_babble_and_fault_file(tmp_path):
    hub = LoopbackHub("127.0.0.1", 0).start()
    spec = f"loopback:line-a@127.0.0.1:{hub.port}"
    tx, rx = open_bus(spec, autostart=False), open_bus(spec, autostart=False)
    try:
        def send(n=3):
            for i in range(n):
                tx.send(can.Message(arbitration_id=0x181, data=bytes([i]), is_extended_id=False))
        send()
        assert len(received(rx)) == 3
        hub.fault("line-a", "cut")
        send()
        assert received(rx) == []
        hub.fault("line-a", "babble")
        send(2)
        assert {m.arbitration_id for m in received(rx)} == {BABBLE_ID}
        hub.fault("line-a", "ok")
        faults = tmp_path / "faults"
        hub.fault_file = faults
        faults.write_text("line-a cut\nother melted\n")     # the bad line is logged and ignored
        time.sleep(0.7)
        send()
        assert received(rx) == []
        faults.write_text("")
        time.sleep(0.7)
        send()
        assert len(received(rx)) == 3
    finally:
        tx.shutdown()
        rx.shutdown()
        hub.stop()
