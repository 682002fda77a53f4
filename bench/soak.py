"""Soak run: repeated ORU-style motions on the real-time daemon with a console polling status.

    .venv/bin/python bench/soak.py [--duration 3600] [--sample 10] [--csv soak.csv]

Simulator, daemon (20 ms real-time clock) and loopback hub run as separate processes; this
process is the operator (joint move to the ready posture, a 50 mm approach along the tool
axis and back, like an ORU insertion, joint move home, again and again) and a second
console polling `status` at 20 Hz. Every `--sample` seconds it records the daemon's RSS
and open files, the recording's size and the cycle statistics, then prints a table:
memory growth per hour (least-squares slope after the first minute), open-file growth,
recording growth rate, overruns, cycles with missing process data (TPDO timeouts) and
protective stops (each recovered with reset + enable and counted with its reason).
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import threading
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from spacearm.console.client import ApiClient  # noqa: E402
from spacearm.base.transport.hub import HubProcess  # noqa: E402
from hil_tests.faults import HOME, READY, start_stack  # noqa: E402
from hil_tests.harness import CpuSteal  # noqa: E402


@dataclass
class Sample:
    t: float
    rss_mb: float
    open_files: int
    recording_mb: float
    cycles: int
    overruns: int
    skipped: int
    period_error_p99_ms: float
    execution_p99_ms: float
    tpdo_timeouts: int
    tpdos_expected: int
    tpdos_received: int
    polls: int
    steal_pct: float         # host CPU steal since the previous sample (VMs)


def proc_rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as handle:
        for line in handle:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def open_files(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/fd"))


class Poller(threading.Thread):
    """The watching console: status at 20 Hz on its own connection."""

    def __init__(self, api: str, rate: float = 20.0):
        super().__init__(daemon=True)
        self.client = ApiClient(api)
        self.period = 1.0 / rate
        self.polls = 0
        self.errors = 0
        self.stop_flag = threading.Event()

    def run(self) -> None:
        next_t = time.monotonic()
        while not self.stop_flag.is_set():
            try:
                self.client.call("status")
                self.polls += 1
            except Exception:
                self.errors += 1
            next_t += self.period
            time.sleep(max(0.0, next_t - time.monotonic()))
        self.client.close()


def operate(stack, until: float, stops: Counter, counts: Counter) -> None:
    """ORU-style cycle: ready posture, approach 50 mm along the tool axis, retract, home."""
    steps = [("move_joints", {"q": READY}), ("move_pose", {"xyz": [0.0, 0.0, 0.05], "rpy": [0, 0, 0],
                                                          "frame": "tool"}),
             ("move_pose", {"xyz": [0.0, 0.0, -0.05], "rpy": [0, 0, 0], "frame": "tool"}),
             ("move_joints", {"q": HOME})]
    i = 0
    counted = None          # the stop already counted (enable may need several tries)
    while time.monotonic() < until:
        cmd, args = steps[i % len(steps)]
        try:
            status = stack.status()
            if status["state"] != "enabled":
                if status["state"] == "stopped" and status["stop_reason"] != counted:
                    counted = status["stop_reason"]
                    stops[counted.split(":")[0] + ": " + _kind(counted)] += 1
                stack.enable()
                counted = None
            motion = stack.call(cmd, **args)["motion"]
            stack.wait_motion(motion, timeout=60)
            counts["motions"] += 1
            i += 1
        except Exception as exc:  # a stop mid-motion: counted above on the next turn
            counts["interrupted"] += 1
            if "protective stop" not in str(exc):
                counts["errors"] += 1
                print(f"  operator: {exc}", file=sys.stderr)
            time.sleep(0.2)


def _kind(reason: str) -> str:
    for words in ("no process data", "heartbeat lost", "following error", "velocity", "boot-up", "EMCY",
                  "emergency", "limit", "force/torque", "watchdog"):
        if words in reason:
            return words
    return reason[:40]


def recording_mb(recording: dict | None) -> float:
    """The recording file's size; 0 before its writer process (a child of the daemon, which
    may still be starting on a busy machine) has created it."""
    if recording is None:
        return float("nan")
    try:
        return Path(recording["path"]).stat().st_size / 1e6
    except FileNotFoundError:
        return 0.0


def slope_per_hour(ts: list[float], ys: list[float]) -> float:
    if len(ts) < 3:
        return float("nan")
    return float(np.polyfit(np.array(ts) / 3600.0, np.array(ys), 1)[0])


def run(duration: float, sample_every: float, csv: Path | None, quiet: bool = False) -> dict:
    hub = HubProcess(rt_priority=50)
    work = Path(tempfile.mkdtemp(prefix="spacearm-soak-"))
    stack = start_stack(hub, work, name=f"soak-{os.getpid()}", rig=False)
    samples: list[Sample] = []
    stops: Counter = Counter()
    counts: Counter = Counter()
    poller = Poller(stack.api)
    sampler = ApiClient(stack.api)       # its own connection: ApiClient is not thread-safe
    try:
        pid = stack.daemon.pid
        poller.start()
        t0 = time.monotonic()
        until = t0 + duration
        operator = threading.Thread(target=operate, args=(stack, until, stops, counts), daemon=True)
        operator.start()
        next_sample = t0
        steal = CpuSteal()
        while time.monotonic() < until or operator.is_alive():
            if time.monotonic() >= next_sample:
                s = sampler.call("status")
                st, rec = s["stats"], s["recording"]
                samples.append(Sample(
                    time.monotonic() - t0, proc_rss_mb(pid), open_files(pid),
                    recording_mb(rec),
                    s["cycle"], st["overruns"], st["skipped_cycles"], st["period_error_p99"] * 1e3,
                    st["execution_p99"] * 1e3, s["network"]["tpdo_timeouts"],
                    s["network"]["expected_tpdos"], s["network"]["tpdos"], poller.polls,
                    100 * steal.fraction()))
                if not quiet:
                    x = samples[-1]
                    print(f"  t={x.t:7.1f} s  rss {x.rss_mb:6.1f} MB  fds {x.open_files:3d}  rec {x.recording_mb:7.2f} MB"
                          f"  overruns {x.overruns}  tpdo timeouts {x.tpdo_timeouts}  motions {counts['motions']}"
                          f"  steal {x.steal_pct:.1f} %",
                          flush=True)
                next_sample += sample_every
            time.sleep(0.2)
        poller.stop_flag.set()
        poller.join(2)
        recording = sampler.call("status")["recording"]
    finally:
        sampler.close()
        stack.close()
        hub.stop()
    if csv:
        with open(csv, "w") as f:
            f.write(",".join(Sample.__dataclass_fields__) + "\n")
            for x in samples:
                f.write(",".join(str(v) for v in vars(x).values()) + "\n")
    warm = [x for x in samples if x.t >= min(60.0, duration / 3)]
    first, last = samples[0], samples[-1]
    elapsed = last.t - first.t
    result = {
        "duration_s": last.t, "cycles": last.cycles, "motions": counts["motions"],
        "polls": last.polls, "poll_errors": poller.errors,
        "rss_start_mb": first.rss_mb, "rss_end_mb": last.rss_mb,
        "rss_growth_mb_per_h": slope_per_hour([x.t for x in warm], [x.rss_mb for x in warm]),
        "open_files_start": first.open_files, "open_files_end": last.open_files,
        "recording_mb_per_h": (last.recording_mb - first.recording_mb) / elapsed * 3600 if elapsed else float("nan"),
        "overruns": last.overruns, "skipped_cycles": last.skipped,
        "period_error_p99_ms_max": max(x.period_error_p99_ms for x in samples),
        "execution_p99_ms_max": max(x.execution_p99_ms for x in samples),
        "tpdo_timeouts": last.tpdo_timeouts, "protective_stops": sum(stops.values()),
        "steal_pct_mean": float(np.mean([x.steal_pct for x in samples[1:]] or [0.0])),
        "steal_pct_max": max([x.steal_pct for x in samples[1:]] or [0.0]),
        "stop_reasons": dict(stops), "interrupted": counts["interrupted"], "errors": counts["errors"],
        # Each sample's SYNC may still have TPDOs in flight: at most one SYNC's worth.
        "tpdos_lost": last.tpdos_expected - last.tpdos_received,
        "tpdos_expected": last.tpdos_expected,
        **recording_check(Path(recording["path"])),
        "workdir": str(work),
    }
    return result


def recording_check(path: Path) -> dict:
    """Cycles in the closed recording and SYNC-counter gaps the clock did not skip on purpose."""
    from spacearm.controller.recording.csv_export import find_cycle_gaps
    from spacearm.controller.recording.mcap_reader import read_recording
    rec = read_recording(path, topics={"/cycle"})
    cycles = rec.messages
    gaps = find_cycle_gaps([m.data["cycle"] for m in cycles], [m.data["t"] for m in cycles])
    sync_gaps = sum(1 for a, b in zip(cycles, cycles[1:]) if b.data["sync"] != a.data["sync"] + 1)
    return {"recorded_cycles": len(cycles), "recording_complete": rec.complete,
            "cycle_gaps": len(gaps), "sync_gaps": sync_gaps}


def print_table(r: dict) -> None:
    rows = [
        ("duration", f"{r['duration_s'] / 60:.1f} min", "3600 s (CI: 60 s)"),
        ("cycles / motions / status polls", f"{r['cycles']} / {r['motions']} / {r['polls']}", "-"),
        ("daemon RSS start -> end", f"{r['rss_start_mb']:.1f} -> {r['rss_end_mb']:.1f} MB", "-"),
        ("RSS growth (slope after warm-up)", f"{r['rss_growth_mb_per_h']:+.2f} MB/h", "~0"),
        ("open files start -> end", f"{r['open_files_start']} -> {r['open_files_end']}", "no growth"),
        ("recording growth", f"{r['recording_mb_per_h']:.1f} MB/h", "linear"),
        ("overruns (skipped cycles)", f"{r['overruns']} ({r['skipped_cycles']})", "0"),
        ("worst 60 s window p99 period error", f"{r['period_error_p99_ms_max']:.2f} ms", "<= 1 ms"),
        ("worst 60 s window p99 execution", f"{r['execution_p99_ms_max']:.2f} ms", "<= 3 ms"),
        ("cycles with missing process data", f"{r['tpdo_timeouts']}", "0"),
        ("TPDO frames lost (expected - received)", f"{r['tpdos_lost']} of {r['tpdos_expected']}", "0"),
        ("recording: cycles / complete / SYNC gaps",
         f"{r['recorded_cycles']} / {r['recording_complete']} / {r['sync_gaps']} "
         f"(cycle gaps {r['cycle_gaps']}: cycles the overruns skipped)", "every SYNC"),
        ("protective stops", f"{r['protective_stops']} {r['stop_reasons'] or ''}", "0"),
        ("host CPU steal (VM) mean / worst sample", f"{r['steal_pct_mean']:.1f} / {r['steal_pct_max']:.1f} %", "-"),
    ]
    w = max(len(a) for a, _, _ in rows)
    print(f"\nsoak on {platform.node()} ({os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}), "
          f"python {platform.python_version()}")
    print(f"{'figure':<{w}}  {'measured':<40}  target")
    for a, b, c in rows:
        print(f"{a:<{w}}  {b:<40}  {c}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=3600.0, help="s of real time (default 3600)")
    parser.add_argument("--sample", type=float, default=10.0, help="s between samples")
    parser.add_argument("--csv", type=Path, default=None, help="write the samples here")
    args = parser.parse_args()
    print_table(run(args.duration, args.sample, args.csv))


if __name__ == "__main__":
    main()
