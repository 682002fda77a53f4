"""Where one lockstep cycle's CPU goes: cProfile of N cycles (8 nodes, in-process bus).

    .venv/bin/python bench/profile_lockstep.py [--cycles 1000] [--record] [--top 25]

Prints CPU and Python calls per cycle, then the functions by own time (thread CPU clock, so
waiting on a loaded machine does not show up as cost). Profiling slows every call: compare
profiles with each other, and take the unprofiled figures from bench/bench_daemon.py.
"""
from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from spacearm.controller.daemon.daemon import Daemon, DaemonOptions  # noqa: E402
from spacearm.firmware_sim.runner import start_simulator  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=1000)
    ap.add_argument("--record", action="store_true", help="record every cycle (MCAP and CAN trace) as the daemon does")
    ap.add_argument("--top", type=int, default=25)
    args = ap.parse_args()
    bus = f"virtual:profile-{time.monotonic_ns()}"
    sim = start_simulator(bus)
    record = Path(tempfile.mkdtemp(prefix="spacearm-profile-")) if args.record else None
    daemon = Daemon(DaemonOptions(bus=bus, clock="lockstep", period=0.02, api=None, record_dir=record))
    try:
        daemon.start()
        daemon.run(max_cycles=50)
        profile = cProfile.Profile(time.thread_time)
        cpu = time.thread_time()
        profile.enable()
        daemon.run(max_cycles=args.cycles)
        profile.disable()
        cpu = time.thread_time() - cpu
    finally:
        daemon.shutdown()
        sim.stop()
    stats = pstats.Stats(profile)
    print(f"{args.cycles} lockstep cycles, recording {'on' if args.record else 'off'}, load {os.getloadavg()[0]:.1f}: "
          f"{1e3 * cpu / args.cycles:.2f} ms thread CPU per cycle (profiled), "
          f"{stats.total_calls / args.cycles:.0f} Python calls per cycle")
    stats.sort_stats("tottime").print_stats(args.top)


if __name__ == "__main__":
    main()
