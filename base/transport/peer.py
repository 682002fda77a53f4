"""A second CAN node in another process, for tests and benchmarks of the transports.

    python -m spacearm.base.transport.peer --bus SPEC MODE [options]

Modes (each opens the bus, prints ``READY`` on stdout, then works; every mode stops by
itself after --timeout seconds at most, and prints one JSON line with its results):

    echo       send every received frame back with arbitration id + 1 (ids < 0x7FF)
    burst      wait for a frame with id --start-id (if given), then send --count frames
               with ids --base-id, data = 4-byte big-endian sequence number
    collect    receive until --count frames arrived, report their sequence numbers
    pdo        emulate --nodes CANopen nodes: on every SYNC (0x080) each node sends
               --tpdos TPDOs (0x180/0x280/0x380/0x480 + node id), or the spacearm PDO set
               with --layout full; data carries the SYNC counter; counts RPDOs (0x200..0x4FF + node) it receives; sends heartbeats
               (0x700 + node) every --heartbeat-ms; stops on a frame with id 0x7FF or timeout.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import can

from spacearm.base.canopen.codes import HEARTBEAT_BASE, RPDO_BASE, SDO_TX_BASE, SYNC_COB_ID_DEFAULT, TPDO_BASE
from spacearm.base.runtime.child_process import module_env, readline_within

ROOT = Path(__file__).resolve().parents[2]

STOP_ID = 0x7FF
SYNC_ID = SYNC_COB_ID_DEFAULT
TPDO_BASES = TPDO_BASE   # CiA 301 pre-defined connection set (base/canopen/codes.py)


def open_any(spec: str) -> can.BusABC:
    """open_bus(spec), plus ``remote:ws://...`` for python-can-remote (benchmark comparison only)."""
    if spec.startswith("remote:"):
        return can.Bus(interface="remote", channel=spec[len("remote:"):])
    sys.path.insert(0, str(ROOT))
    from spacearm.base.transport import open_bus

    return open_bus(spec)


def _ready() -> None:
    print("READY", flush=True)


def mode_echo(bus: can.BusABC, args) -> dict:
    n = 0
    end = time.monotonic() + args.timeout
    while time.monotonic() < end:
        msg = bus.recv(0.1)
        if msg is None:
            continue
        if msg.arbitration_id == STOP_ID and not msg.is_extended_id:
            break
        if msg.arbitration_id < 0x7FE:
            bus.send(can.Message(arbitration_id=msg.arbitration_id + 1, data=msg.data,
                                 is_extended_id=msg.is_extended_id))
            n += 1
    return {"echoed": n}


def mode_burst(bus: can.BusABC, args) -> dict:
    if args.start_id is not None:
        end = time.monotonic() + args.timeout
        while time.monotonic() < end:
            msg = bus.recv(0.1)
            if msg is not None and msg.arbitration_id == args.start_id:
                break
        else:
            return {"sent": 0, "error": "no start frame"}
    t0 = time.perf_counter()
    for i in range(args.count):
        bus.send(can.Message(arbitration_id=args.base_id, data=i.to_bytes(4, "big"), is_extended_id=False))
    return {"sent": args.count, "seconds": time.perf_counter() - t0}


def mode_collect(bus: can.BusABC, args) -> dict:
    seqs = []
    end = time.monotonic() + args.timeout
    while len(seqs) < args.count and time.monotonic() < end:
        msg = bus.recv(0.1)
        if msg is not None and msg.arbitration_id == args.base_id:
            seqs.append(int.from_bytes(msg.data[:4], "big"))
    return {"received": len(seqs), "in_order": seqs == sorted(seqs), "seqs_ok": seqs == list(range(len(seqs)))}


def mode_pdo(bus: can.BusABC, args) -> dict:
    nodes, frames_per_sync = pdo_layout(args.layout, args.nodes, args.tpdos)
    hb_sent = [0]
    syncs = 0
    rpdos: dict[int, int] = {}
    stop = threading.Event()
    send_lock = threading.Lock()

    def heartbeats():
        period = args.heartbeat_ms / 1000.0
        nxt = time.monotonic()
        while not stop.is_set():
            nxt += period
            with send_lock:
                for node in nodes:
                    try:
                        bus.send(can.Message(arbitration_id=HEARTBEAT_BASE + node, data=b"\x05", is_extended_id=False))
                        hb_sent[0] += 1
                    except can.CanError:
                        pass
            stop.wait(max(0.0, nxt - time.monotonic()))

    hb = None
    if args.heartbeat_ms > 0:
        hb = threading.Thread(target=heartbeats, daemon=True)
        hb.start()
    end = time.monotonic() + args.timeout
    try:
        while time.monotonic() < end:
            msg = bus.recv(0.1)
            if msg is None or msg.is_extended_id:
                continue
            aid = msg.arbitration_id
            if aid == STOP_ID:
                break
            if aid == SYNC_ID:
                counter = msg.data[:4] if len(msg.data) >= 4 else syncs.to_bytes(4, "big")
                syncs += 1
                with send_lock:
                    for cob, size in frames_per_sync:
                        bus.send(can.Message(arbitration_id=cob, data=(counter + bytes(4))[:size],
                                             is_extended_id=False))
            elif RPDO_BASE[0] <= aid < SDO_TX_BASE and (aid & 0x7F) in nodes:
                rpdos[aid] = rpdos.get(aid, 0) + 1
    finally:
        stop.set()
        if hb is not None:
            hb.join(1)
    return {"syncs": syncs, "tpdos_sent": syncs * len(frames_per_sync), "rpdos": sum(rpdos.values()),
            "heartbeats_sent": hb_sent[0], "rpdo_by_id": {hex(k): v for k, v in rpdos.items()}}


# The spacearm PDO set (see bench/bench_bus.py for the assumptions): node -> [(COB-ID, bytes)]
FULL_LAYOUT = {
    **{n: [(TPDO_BASE[0] + n, 6), (TPDO_BASE[1] + n, 6)] for n in range(1, 7)},   # joint drives: TPDO1, TPDO2
    7: [(0x187, 8)],                                                 # end-effector
    8: [(0x188, 8), (0x288, 6)],                                     # F/T sensor
}


def pdo_layout(layout: str, nodes: int = 8, tpdos: int = 4) -> tuple[list[int], list[tuple[int, int]]]:
    """(node ids, [(COB-ID, length)] sent on every SYNC)."""
    if layout == "full":
        return sorted(FULL_LAYOUT), [f for n in sorted(FULL_LAYOUT) for f in FULL_LAYOUT[n]]
    ids = list(range(1, nodes + 1))
    return ids, [(base + n, 8) for n in ids for base in TPDO_BASES[:tpdos]]


MODES = {"echo": mode_echo, "burst": mode_burst, "collect": mode_collect, "pdo": mode_pdo}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="peer")
    p.add_argument("--bus", required=True)
    p.add_argument("mode", choices=sorted(MODES))
    p.add_argument("--count", type=int, default=1000)
    p.add_argument("--base-id", type=lambda s: int(s, 0), default=0x123)
    p.add_argument("--start-id", type=lambda s: int(s, 0), default=None)
    p.add_argument("--nodes", type=int, default=8)
    p.add_argument("--tpdos", type=int, default=4)
    p.add_argument("--layout", choices=("uniform", "full"), default="uniform",
                   help="uniform: --nodes x --tpdos 8-byte TPDOs; full: the spacearm PDO set")
    p.add_argument("--heartbeat-ms", type=float, default=0)
    p.add_argument("--timeout", type=float, default=30.0)
    args = p.parse_args(argv)
    try:
        bus = open_any(args.bus)
    except Exception as exc:  # report the reason to the parent in one line
        print(json.dumps({"error": f"{type(exc).__name__}: {exc}"}), flush=True)
        return 3
    try:
        _ready()
        result = MODES[args.mode](bus, args)
    finally:
        bus.shutdown()
    print(json.dumps(result), flush=True)
    return 0


class Peer:
    """Parent-side handle: starts the peer process and waits for READY (with a timeout)."""

    def __init__(self, spec: str, mode: str, *extra: str, ready_timeout: float = 20.0, timeout: float = 30.0):
        self.cmd = [sys.executable, "-m", "spacearm.base.transport.peer", "--bus", spec, mode,
                    "--timeout", str(timeout), *extra]
        self.proc = subprocess.Popen(self.cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     cwd=str(ROOT), env=module_env())
        self._lines: list[str] = []
        line = readline_within(self.proc, ready_timeout) or f"(no READY within {ready_timeout:.0f} s)"
        if line.strip() != "READY":
            self.kill()
            err = self.proc.stderr.read() if self.proc.stderr else ""
            raise RuntimeError(f"peer {' '.join(self.cmd)} did not start: {line.strip()} {err[-2000:]}")

    def result(self, timeout: float = 30.0) -> dict:
        try:
            out, err = self.proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.kill()
            raise RuntimeError(f"peer {' '.join(self.cmd)} did not finish within {timeout} s")
        lines = [ln for ln in out.splitlines() if ln.startswith("{")]
        if self.proc.returncode != 0 or not lines:
            raise RuntimeError(f"peer failed (rc={self.proc.returncode}): {out[-1000:]} {err[-2000:]}")
        return json.loads(lines[-1])

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            try:
                self.proc.communicate(timeout=5)
            except Exception:
                pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.kill()


if __name__ == "__main__":
    sys.exit(main())
