#!/usr/bin/env python3
"""Bus transport benchmark: latency, frame loss and computed bus load.

    .venv/bin/python bench/bench_bus.py [--duration 60] [--transports virtual,loopback,socketcan]

Per transport (virtual: responder in a thread of this process; loopback and socketcan: the
responder is another process, base/transport/peer.py):

1. SYNC to last TPDO received, 8 nodes x 4 TPDOs (32 x 8-byte frames per SYNC), at
   --latency-hz for --latency-syncs SYNCs: median and p99 (target p99 <= 2 ms).
2. Frames lost over --duration seconds at 50 Hz with the full spacearm PDO set (SYNC, 7 RPDOs
   from the master, 15 TPDOs back, heartbeats of 8 nodes every 100 ms), and the SYNC to last
   TPDO latency of that run.
3. Computed bus load at 1 Mbit/s for the full PDO set at 50 Hz and 250 Hz (no transport
   involved: worst-case bit stuffing, see the assumption table printed).

4. Supervision timing of the master (drivers/network.py) against the in-process simulator:
   the worst free-running cycle call (read, write, SYNC, events: they never wait for process
   data), how soon a silent node is declared lost (bound: 3 heartbeat periods), and how soon
   the drives fault once the controller's heartbeat stops (consumer timeout 1016h). These
   were wall-clock asserts of tests/canopen; the tests now check the behaviour, the time is
   here (--supervision-runs, 0 skips it), printed with the machine load and CPU steal.

socketcan runs only where vcan0 exists. --compare-can-remote also measures python-can-remote's
websocket server (if that package is installed) on 127.0.0.1 for comparison.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import socket
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path
from types import SimpleNamespace

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import can  # noqa: E402

from spacearm.base.transport.hub import HubProcess  # noqa: E402
from spacearm.base.transport.peer import STOP_ID, SYNC_ID, Peer, mode_pdo, pdo_layout  # noqa: E402
from spacearm.base.transport.peer import open_any as open_bus  # noqa: E402

LATENCY_TARGET_MS = 2.0
BUSLOAD_TARGET_PCT = 70.0
BITRATE = 1_000_000

# ----------------------------------------------------------------------------- bus load
# (what, COB-ID base, data bytes, frames per SYNC cycle, note)
PDO_SET = [
    ("SYNC", 0x080, 0, 1, "master, no counter"),
    ("joint RPDO1 x6", 0x200, 8, 6, "controlword 2 + target position 4 + 2 (velocity offset / pad): 8 B"),
    ("joint TPDO1 x6", 0x180, 6, 6, "statusword 2 + position actual 4"),
    ("joint TPDO2 x6", 0x280, 6, 6, "velocity actual 4 + torque actual 2"),
    ("end-effector RPDO1", 0x207, 8, 1, "command word + setpoints: 8 B assumed"),
    ("end-effector TPDO1", 0x187, 8, 1, "status + feedback: 8 B assumed"),
    ("F/T TPDO1", 0x188, 8, 1, "Fx Fy Fz Tx (4 x int16)"),
    ("F/T TPDO2", 0x288, 6, 1, "Ty Tz (2 x int16) + status 2"),
]
HEARTBEAT = ("heartbeat x9", 0x700, 1, 9, "8 nodes + master, every 100 ms (10 Hz, not per SYNC)")


def frame_bits(nbytes: int, extended: bool = False) -> int:
    """Worst-case bits on the wire for a classic CAN data frame, including the 3-bit
    interframe space. Stuffable part: SOF..CRC = 34 + 8n bits (11-bit id) or 54 + 8n (29-bit);
    at most one stuff bit per 4 bits after the first: floor((g - 1) / 4)."""
    g = (54 if extended else 34) + 8 * nbytes
    fixed = 1 + 2 + 7 + 3  # CRC delimiter, ACK slot + delimiter, EOF, IFS (not stuffed)
    return g + (g - 1) // 4 + fixed


def bus_load(rate_hz: float) -> tuple[float, float, int]:
    """(bits per second, load %, frames per second) of the full PDO set at rate_hz SYNC."""
    bits = sum(frame_bits(n) * k for _, _, n, k, _ in PDO_SET) * rate_hz
    frames = sum(k for *_, k, _ in PDO_SET) * rate_hz
    _, _, hn, hk, _ = HEARTBEAT
    bits += frame_bits(hn) * hk * 10
    frames += hk * 10
    return bits, 100.0 * bits / BITRATE, int(frames)


# ----------------------------------------------------------------------------- helpers
def vcan_exists() -> bool:
    return Path("/sys/class/net/vcan0").exists()


def pct(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    s = sorted(values)
    k = max(0, min(len(s) - 1, int(round(q / 100.0 * len(s) + 0.5)) - 1))
    return s[k]


class Responder:
    """The node emulator on the other side: a process (multi-process transports) or a thread."""

    def __init__(self, spec: str, layout: str, heartbeat_ms: float, timeout: float, in_process: bool):
        self.in_process = in_process
        if in_process:
            self.bus = open_bus(spec)
            args = SimpleNamespace(layout=layout, nodes=8, tpdos=4, heartbeat_ms=heartbeat_ms, timeout=timeout)
            self._result: dict = {}
            self.thread = threading.Thread(target=lambda: self._result.update(mode_pdo(self.bus, args)),
                                           daemon=True)
            self.thread.start()
        else:
            self.peer = Peer(spec, "pdo", "--layout", layout, "--heartbeat-ms", str(heartbeat_ms),
                             timeout=timeout)

    def result(self) -> dict:
        if self.in_process:
            self.thread.join(10)
            self.bus.shutdown()
            return self._result
        return self.peer.result(30)

    def kill(self):
        if not self.in_process:
            self.peer.kill()


def _drain(bus, quiet=0.2, limit=1.0) -> int:
    """Read until quiet (or limit); returns the number of heartbeats seen."""
    end = time.monotonic() + limit
    hb = 0
    while time.monotonic() < end:
        msg = bus.recv(quiet)
        if msg is None:
            break
        hb += 0x700 < msg.arbitration_id < 0x780
    return hb


def run_cycles(spec: str, in_process: bool, layout: str, rate_hz: float, *, cycles: int | None = None,
               duration: float | None = None, rpdos: list[tuple[int, int]] | None = None,
               heartbeat_ms: float = 0.0) -> dict:
    """Master side: SYNC (+ RPDOs) every 1/rate_hz; count TPDOs per SYNC; latency to the last one."""
    _, tpdo_frames = pdo_layout(layout)
    per_sync = len(tpdo_frames)
    total_time = duration if duration is not None else cycles / rate_hz
    bus = open_bus(spec)  # before the responder, so it hears the responder's first frames
    try:
        resp = Responder(spec, layout, heartbeat_ms, timeout=total_time + 60, in_process=in_process)
    except BaseException:
        bus.shutdown()
        raise
    try:
        heartbeats = _drain(bus, 0.3)
        counts: dict[int, int] = {}
        sent_at: dict[int, float] = {}
        latency: list[float] = []
        late = 0
        out_of_order = 0
        last_counter_seen: dict[int, int] = {}
        period = 1.0 / rate_hz
        t_start = time.perf_counter()
        next_t = t_start
        n = 0
        rpdo_msgs = [can.Message(arbitration_id=cob, data=bytes(size), is_extended_id=False)
                     for cob, size in (rpdos or [])]

        def handle(msg, now):
            nonlocal heartbeats, late, out_of_order
            aid = msg.arbitration_id
            if 0x700 < aid < 0x780:
                heartbeats += 1
                return
            if len(msg.data) < 4:
                return
            c = int.from_bytes(msg.data[:4], "big")
            if c not in sent_at:
                return
            if last_counter_seen.get(aid, -1) > c:
                out_of_order += 1
            last_counter_seen[aid] = c
            counts[c] = counts.get(c, 0) + 1
            if counts[c] == per_sync:
                latency.append((now - sent_at[c]) * 1e3)
                if c != n - 1:
                    late += 1

        while (cycles is not None and n < cycles) or (duration is not None and next_t - t_start < duration):
            now = time.perf_counter()
            while now < next_t:
                msg = bus.recv(next_t - now)
                now = time.perf_counter()
                if msg is not None:
                    handle(msg, now)
            sent_at[n] = time.perf_counter()
            bus.send(can.Message(arbitration_id=SYNC_ID, data=n.to_bytes(4, "big"), is_extended_id=False))
            for m in rpdo_msgs:
                bus.send(m)
            n += 1
            next_t += period
            if next_t < time.perf_counter() - period:  # fell behind (machine busy): do not burst
                next_t = time.perf_counter()
        # collect stragglers
        end = time.perf_counter() + 1.0
        while time.perf_counter() < end:
            msg = bus.recv(0.1)
            if msg is not None:
                handle(msg, time.perf_counter())
        bus.send(can.Message(arbitration_id=STOP_ID, is_extended_id=False))
        end = time.perf_counter() + 0.5  # heartbeats the responder sent before it saw STOP
        while time.perf_counter() < end:
            msg = bus.recv(0.1)
            if msg is not None:
                handle(msg, time.perf_counter())
        peer = resp.result()
        elapsed = time.perf_counter() - t_start
    finally:
        resp.kill()
        bus.shutdown()
    expected_tpdos = n * per_sync
    got_tpdos = sum(counts.values())
    return {
        "syncs": n, "seconds": elapsed, "tpdos_expected": expected_tpdos, "tpdos_received": got_tpdos,
        "responder_syncs": peer.get("syncs"), "rpdos_sent": n * len(rpdo_msgs), "rpdos_received": peer.get("rpdos"),
        "heartbeats_sent": peer.get("heartbeats_sent", 0), "heartbeats_received": heartbeats,
        "lost": (n - (peer.get("syncs") or 0)) + (expected_tpdos - got_tpdos) + (n * len(rpdo_msgs) - (peer.get("rpdos") or 0))
        + max(0, peer.get("heartbeats_sent", 0) - heartbeats),
        "frames_total": n + expected_tpdos + n * len(rpdo_msgs) + peer.get("heartbeats_sent", 0),
        "latency_ms": latency, "late_cycles": late, "out_of_order": out_of_order,
    }


def baseline_jitter(cycles: int, rate_hz: float) -> list[float]:
    """The same SYNC -> 32 replies pattern between two processes over a raw Unix socketpair (no
    python-can, no hub): what this machine's scheduler alone costs. A high p99 here means the
    machine is noisy and every transport's tail will be too."""
    a, b = socket.socketpair()
    pid = os.fork()
    if pid == 0:  # child: answer every request with 32 14-byte records
        a.close()
        try:
            while True:
                d = b.recv(64)
                if not d or d == b"q":
                    break
                for _ in range(32):
                    b.send(b"x" * 14)
        finally:
            os._exit(0)
    b.close()
    lat = []
    try:
        period = 1.0 / rate_hz
        for _ in range(cycles):
            t0 = time.perf_counter()
            a.send(b"s")
            got = 0
            while got < 32 * 14:
                got += len(a.recv(4096))
            lat.append((time.perf_counter() - t0) * 1e3)
            time.sleep(max(0.0, t0 + period - time.perf_counter()))
        a.send(b"q")
    finally:
        a.close()
        os.waitpid(pid, 0)
    return lat


# ----------------------------------------------------------------------------- can-remote
class CanRemoteServer:
    """python-can-remote's websocket server on 127.0.0.1 (comparison only)."""

    def __init__(self):
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            self.port = s.getsockname()[1]
        self.proc = subprocess.Popen([sys.executable, "-m", "can_remote", "-H", "127.0.0.1", "-p", str(self.port),
                                      "-i", "virtual", "-c", "bench"], stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline:
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.5).close()
                return
            except OSError:
                time.sleep(0.1)
        self.stop()
        raise RuntimeError("python-can-remote server did not start")

    def stop(self):
        self.proc.terminate()
        try:
            self.proc.wait(5)
        except subprocess.TimeoutExpired:
            self.proc.kill()


# ----------------------------------------------------------------------------- supervision
def supervision_timing(runs: int) -> list[tuple[str, str, str, str, str]]:
    """Rows for section 4: `runs` rounds of each measurement, the worst of them reported."""
    import uuid

    from hil_tests.harness import CpuSteal
    from spacearm.base.canopen import od
    from spacearm.drivers.network import ArmCommand, ArmNetwork
    from spacearm.firmware_sim.runner import Simulator

    calls, losses, consumer = [], [], []
    steal, load = CpuSteal(), os.getloadavg()[0]
    for _ in range(runs):
        spec = f"virtual:supervision-{uuid.uuid4().hex[:8]}"
        sim = Simulator(spec).start()
        net = ArmNetwork(spec)
        try:
            net.boot()
            net.enable_all()
            q0 = net.read().joints[0].position
            due = time.monotonic()
            for k in range(50):                  # free running at 50 Hz
                started = time.monotonic()
                net.read()
                net.write(ArmCommand(joint_positions=[q0 + 0.001 * k]))
                net.send_sync()
                net.poll_events()
                calls.append(time.monotonic() - started)
                due += 0.02
                time.sleep(max(0.0, due - time.monotonic()))
            for name in ("joint_1", "ft_sensor"):
                period = net.config.node(name).heartbeat_period
                net.poll_events()
                started = time.monotonic()
                sim.node(name).faults.silent = True
                lost = []
                while not lost and time.monotonic() < started + 5.0:
                    time.sleep(0.002)
                    lost = [e for e in net.poll_events() if e.kind == "heartbeat_lost" and e.node == name]
                losses.append(((lost[0].time if lost else float("inf")) - started, period))
                sim.node(name).faults.silent = False
                while not net.read().nodes[name].alive and time.monotonic() < started + 10.0:
                    time.sleep(0.01)
            drives = [sim.node(i) for i in range(1, 7)]
            timeout = (drives[0].get(od.CONSUMER_HEARTBEAT, 1) & 0xFFFF) / 1e3
            net.close()
            started = time.monotonic()
            while (not all(d.error_code == od.EMCY_HEARTBEAT_ERROR for d in drives)
                   and time.monotonic() < started + 5.0):
                time.sleep(0.002)
            consumer.append((time.monotonic() - started, timeout))
        finally:
            net.close()
            sim.stop()
    where = "(master)"
    worst_loss, period = max(losses)
    worst_consumer, timeout = max(consumer)
    return [
        (where, f"free-running cycle call (read+write+SYNC+events), {len(calls)} calls, median / worst",
         f"{1e3 * statistics.median(calls):.3f} / {1e3 * max(calls):.3f} ms", "never waits", "figure"),
        (where, f"silent node -> heartbeat_lost, worst of {len(losses)}",
         f"{1e3 * worst_loss:.0f} ms", f"<= {3e3 * period:.0f} ms (3 periods)",
         "PASS" if worst_loss <= 3 * period else "FAIL"),
        (where, f"controller closed -> all 6 drives fault (its last heartbeat up to 1 period earlier), worst of {len(consumer)}",
         f"{1e3 * worst_consumer:.0f} ms", f"consumer timeout {1e3 * timeout:.0f} ms", "figure"),
        (where, "  machine load / host CPU steal during these",
         f"{max(load, os.getloadavg()[0]):.1f} / {100 * steal.fraction():.1f} %", "", "reference"),
    ]


# ----------------------------------------------------------------------------- main
def machine_info() -> list[str]:
    cpu = "?"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    load = os.getloadavg() if hasattr(os, "getloadavg") else ("?",)
    return [
        f"machine : {platform.node()} {platform.machine()}, {os.cpu_count()} cpus ({cpu})",
        f"os      : {platform.platform()}",
        f"python  : {platform.python_version()}, python-can {can.__version__}",
        f"load avg: {' '.join(f'{x:.2f}' for x in load)} (at start)",
        f"date    : {time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}",
    ]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=60.0, help="seconds of the 50 Hz loss run (issue: 600)")
    ap.add_argument("--latency-syncs", type=int, default=2000)
    ap.add_argument("--latency-hz", type=float, default=250.0)
    ap.add_argument("--transports", default="", help="comma list (default: virtual,loopback[,socketcan])")
    ap.add_argument("--compare-can-remote", action="store_true",
                    help="also measure python-can-remote (pip install python-can-remote)")
    ap.add_argument("--json", type=Path, help="also write the raw figures here")
    ap.add_argument("--supervision-runs", type=int, default=3, help="rounds of section 4 (0: skip it)")
    args = ap.parse_args(argv)

    transports = [t for t in args.transports.split(",") if t and t != "none"] if args.transports else \
        ["virtual", "loopback"] + (["socketcan"] if vcan_exists() else [])
    print("\n".join(machine_info()))
    print()

    rows: list[tuple[str, str, str, str, str]] = []
    raw: dict = {"machine": machine_info(), "args": vars(args) | {"json": str(args.json)}, "results": {}}
    hub = None
    remote = None
    failed = False
    base = baseline_jitter(args.latency_syncs, args.latency_hz)
    rows.append(("(baseline)", f"raw socketpair, 2 processes, 32 replies @{args.latency_hz:g} Hz, median / p99",
                 f"{statistics.median(base):.3f} / {pct(base, 99):.3f} ms", "", "machine noise reference"))
    raw["baseline_p99_ms"] = pct(base, 99)
    try:
        for kind in transports + (["can-remote"] if args.compare_can_remote else []):
            if kind == "virtual":
                spec, in_proc = "virtual:bench", True
            elif kind == "loopback":
                hub = hub or HubProcess()
                spec, in_proc = f"loopback:bench@{hub.host}:{hub.port}", False
            elif kind == "socketcan":
                if not vcan_exists():
                    rows.append((kind, "all", "not run", "", "no vcan0 here"))
                    continue
                spec, in_proc = "socketcan:vcan0", False
            elif kind == "can-remote":
                try:
                    import can_remote  # noqa: F401
                except ImportError:
                    rows.append((kind, "all", "not run", "", "python-can-remote not installed"))
                    continue
                remote = CanRemoteServer()
                spec, in_proc = f"remote:ws://127.0.0.1:{remote.port}/", False
            else:
                raise SystemExit(f"unknown transport {kind}")
            label = kind if kind != "can-remote" else "can-remote (comparison)"
            print(f"[{label}] latency: {args.latency_syncs} SYNCs at {args.latency_hz:g} Hz, 8 nodes x 4 TPDOs ...",
                  flush=True)
            nb = max(100, args.latency_syncs // 4)
            before = baseline_jitter(nb, args.latency_hz)
            lat = run_cycles(spec, in_proc, "uniform", args.latency_hz, cycles=args.latency_syncs)
            after = baseline_jitter(nb, args.latency_hz)
            print(f"[{label}] loss run: {args.duration:g} s at 50 Hz, full PDO set + heartbeats ...", flush=True)
            loss = run_cycles(spec, in_proc, "full", 50.0, duration=args.duration,
                              rpdos=[(0x200 + n, 8) for n in range(1, 8)], heartbeat_ms=100.0)
            raw["results"][kind] = {"latency": lat | {"latency_ms": None}, "loss": loss | {"latency_ms": None},
                                    "latency_p99_ms": pct(lat["latency_ms"], 99)}
            med, p99 = statistics.median(lat["latency_ms"] or [float("nan")]), pct(lat["latency_ms"], 99)
            ok_lat = p99 <= LATENCY_TARGET_MS and lat["tpdos_received"] == lat["tpdos_expected"]
            target_note = "" if kind != "can-remote" else " (not counted)"
            rows.append((label, f"SYNC->last TPDO, 8 nodes x 4 TPDOs @{args.latency_hz:g} Hz, median",
                         f"{med:.3f} ms", "", f"n={len(lat['latency_ms'])}"))
            rows.append((label, f"SYNC->last TPDO, 8 nodes x 4 TPDOs @{args.latency_hz:g} Hz, p99",
                         f"{p99:.3f} ms (max {max(lat['latency_ms'] or [float('nan')]):.3f})",
                         f"<= {LATENCY_TARGET_MS:g} ms", ("PASS" if ok_lat else "FAIL") + target_note))
            rows.append((label, "  machine noise just before / after (raw socketpair p99)",
                         f"{pct(before, 99):.3f} / {pct(after, 99):.3f} ms", "", "reference"))
            rows.append((label, f"  frames lost in that run ({lat['tpdos_expected'] + lat['syncs']} frames)",
                         str(lat["tpdos_expected"] - lat["tpdos_received"] + lat["syncs"] - (lat["responder_syncs"] or 0)),
                         "0", "PASS" if lat["tpdos_expected"] == lat["tpdos_received"] else "FAIL"))
            lm = loss["latency_ms"]
            rows.append((label, f"frames lost, 50 Hz full PDO set + heartbeats, {loss['seconds']:.0f} s",
                         f"{loss['lost']} of {loss['frames_total']}", "0",
                         ("PASS" if loss["lost"] == 0 and loss["out_of_order"] == 0 else "FAIL") + target_note))
            rows.append((label, "  SYNC->last TPDO in that run (15 TPDOs), median / p99",
                         f"{statistics.median(lm or [float('nan')]):.3f} / {pct(lm, 99):.3f} ms",
                         f"p99 <= {LATENCY_TARGET_MS:g} ms",
                         ("PASS" if pct(lm, 99) <= LATENCY_TARGET_MS else "FAIL") + target_note))
            if kind != "can-remote":
                failed |= not ok_lat or loss["lost"] != 0 or loss["out_of_order"] != 0
    finally:
        if hub:
            hub.stop()
        if remote:
            remote.stop()

    if args.supervision_runs > 0:
        print(f"[master] supervision timing: {args.supervision_runs} rounds ...", flush=True)
        rows += supervision_timing(args.supervision_runs)

    for hz in (50, 250):
        bits, load, fps = bus_load(hz)
        rows.append(("(computed)", f"bus load @1 Mbit/s, full PDO set, SYNC {hz} Hz",
                     f"{load:.1f} % ({bits / 1000:.0f} kbit/s, {fps} frames/s)", f"< {BUSLOAD_TARGET_PCT:g} %",
                     "PASS" if load < BUSLOAD_TARGET_PCT else "FAIL"))

    widths = [max(len(r[i]) for r in rows + [("transport", "measurement", "measured", "target", "result")])
              for i in range(5)]
    line = "  ".join("-" * w for w in widths)
    print()
    print("  ".join(h.ljust(w) for h, w in zip(("transport", "measurement", "measured", "target", "result"), widths)))
    print(line)
    for r in rows:
        print("  ".join(c.ljust(w) for c, w in zip(r, widths)))
    print()
    load = os.getloadavg() if hasattr(os, "getloadavg") else ()
    print(f"load avg at end: {' '.join(f'{x:.2f}' for x in load)} -- other processes competing for the 2 cores "
          f"(a QEMU test VM, a test run) inflate the latency tails; compare runs on a quiet machine.")
    print(f"Loss run: {args.duration:g} s per transport (the issue asks for 600 s: --duration 600).")
    print("Latency: measured in the master process from SYNC send() to recv() of the last TPDO of that SYNC;")
    print("responder = one process emulating all nodes (virtual: a thread, virtual is in-process only).")
    print()
    print("Bus load assumptions (classic CAN, 11-bit ids, worst-case bit stuffing, 3-bit IFS):")
    for what, cob, n, k, note in PDO_SET + [HEARTBEAT]:
        print(f"  {what:<20} 0x{cob:03X}  {n} B  {frame_bits(n):>3} bits  x{k}  {note}")
    print("  frame bits = 34 + 8n stuffable + floor((33 + 8n) / 4) stuff + 13 fixed (CRC delim 1, ACK 2, EOF 7, IFS 3)")
    if args.json:
        args.json.write_text(json.dumps(raw, indent=2, default=str))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
