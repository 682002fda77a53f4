"""Where one lockstep cycle's CPU goes.

    .venv/bin/python bench/profile_lockstep.py [--cycles 1000] [--record] [--top 25]
    .venv/bin/python bench/profile_lockstep.py --transport loopback [--cycles 3000] [--top 15]

    .venv/bin/python bench/profile_lockstep.py --compare-core [--cycles 4000]

--compare-core: the compiled core's saving (firmware_sim/_simcore.c) in one run, the core
switched on and off every 25 cycles (compare_core).

In-process bus (default): cProfile of N cycles (8 nodes), CPU and Python calls per cycle,
then the functions by own time (thread CPU clock, so waiting on a loaded machine does not
show up as cost).

Loopback: the simulator runs in its own process and frames go through the hub, so the work
is spread over threads of three processes; cProfile sees one thread only. py-spy (PyPI, the
`profile` extra) samples the daemon process and the simulator process while the cycles run
and this prints each process's functions by own samples (on-CPU only, every thread), plus
the process CPU per cycle of both sides. Profiling slows every call: compare profiles with
each other, and take the unprofiled figures from bench/bench_daemon.py.
"""
from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from spacearm.controller.daemon.daemon import Daemon, DaemonOptions  # noqa: E402
from spacearm.firmware_sim.runner import start_simulator  # noqa: E402

sys.path.insert(0, str(ROOT / "bench"))
from bench_daemon import process_cpu  # noqa: E402


def profile_in_process(args) -> None:
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
    print_parts(stats, args.cycles)
    stats.sort_stats("tottime").print_stats(args.top)


# Which part of the cycle a function belongs to, by where it lives (first match wins).
PARTS = (
    ("simulator: plant physics", ("firmware_sim/plant", "firmware_sim/rigid_body", "firmware_sim/effects",
                                  "firmware_sim/contact")),
    ("simulator: drives (CiA 402, servo)", ("firmware_sim/joint_drive", "firmware_sim/cia402_state_machine",
                                            "firmware_sim/end_effector", "firmware_sim/ft_sensor")),
    ("simulator: object dictionary, PDO/SDO engine", ("firmware_sim/node", "firmware_sim/pdo_engine", "firmware_sim/od_cyclic",
                                                      "firmware_sim/sdo_server", "firmware_sim/sdo_session")),
    ("simulator: SYNC routing", ("firmware_sim/",)),
    ("bus: transport and frame delivery", ("base/transport", "site-packages/can/")),
    ("master: PDO decode/encode, device drivers", ("drivers/",)),
    ("controller: recording hand-off", ("controller/recording", "controller/daemon/recorder")),
    ("controller: supervision", ("controller/daemon/supervision",)),
    ("controller: daemon cycle, modes, planning", ("controller/",)),
    ("kinematics and spatial math", ("base/kinematics", "base/spatial")),
    ("other spacearm code", ("/work/", "spacearm")),
)


def part_of(filename: str, name: str = "") -> str:
    if "_simcore." in name:        # the compiled core's functions are built-ins to cProfile
        return "simulator: compiled core (_simcore.c)"
    for part, places in PARTS:
        if any(place in filename for place in places):
            return part
    return "Python built-ins and libraries"


def print_parts(stats: pstats.Stats, cycles: int) -> None:
    """Own (exclusive) CPU per cycle grouped by part of the cycle: the bench's docstring table."""
    own: Counter = Counter()
    for (filename, _line, name), (_cc, _nc, tottime, _ct, _callers) in stats.stats.items():
        own[part_of(filename, name)] += tottime
    total = sum(own.values())
    print(f"\n{'part of the cycle (own CPU, profiled)':<48} {'ms/cycle':>9} {'share':>7}")
    for part, seconds in own.most_common():
        print(f"{part:<48} {1e3 * seconds / cycles:9.3f} {100 * seconds / total:6.1f} %")
    print()


def own_samples(raw: Path) -> tuple[Counter, int]:
    """py-spy's raw (collapsed) stacks -> samples per innermost function, and the total."""
    counts: Counter = Counter()
    total = 0
    for line in raw.read_text().splitlines():
        stack, _, n = line.rpartition(" ")
        if not stack or not n.isdigit():
            continue
        frame = stack.rsplit(";", 1)[-1]
        name, _, where = frame.partition(" (")
        where = where.rstrip(")").rsplit(":", 1)[0]
        counts[f"{name} ({'/'.join(Path(where).parts[-2:])})"] += int(n)
        total += int(n)
    return counts, total


def profile_loopback(args) -> None:
    from spacearm.base.transport.hub import HubProcess

    spy = shutil.which("py-spy") or str(Path(sys.executable).parent / "py-spy")
    if not Path(spy).exists():
        sys.exit("profile_lockstep: py-spy not found (pip install py-spy, the `profile` extra)")
    hub = HubProcess()
    bus = hub.spec(f"profile-{time.monotonic_ns()}")
    sim = subprocess.Popen([sys.executable, "-m", "spacearm.console.main", "sim", "--bus", bus], cwd=ROOT,
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    for line in sim.stdout:
        if "nodes ready" in line:
            break
    out = Path(tempfile.mkdtemp(prefix="spacearm-profile-"))
    record = out / "runs" if args.record else None
    daemon = Daemon(DaemonOptions(bus=bus, clock="lockstep", period=0.02, api=None, record_dir=record))
    spies = {}
    try:
        daemon.start()
        daemon.run(max_cycles=50)
        for name, pid in (("daemon", os.getpid()), ("simulator", sim.pid), ("hub", hub.proc.pid)):
            spies[name] = subprocess.Popen([spy, "record", "--pid", str(pid), "--format", "raw", "--nonblocking",
                                            "--rate", "500", "--output", str(out / f"{name}.txt")],
                                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(1.0)       # py-spy attaches
        cpu = {name: process_cpu(pid) for name, pid in (("daemon", os.getpid()), ("simulator", sim.pid),
                                                         ("hub", hub.proc.pid))}
        wall = time.monotonic()
        daemon.run(max_cycles=args.cycles)
        wall = time.monotonic() - wall
        cpu = {name: process_cpu(pid) - cpu[name] for name, pid in (("daemon", os.getpid()), ("simulator", sim.pid),
                                                                      ("hub", hub.proc.pid))}
        for proc in spies.values():
            proc.send_signal(signal.SIGINT)
        for proc in spies.values():
            proc.wait(30)
    finally:
        daemon.shutdown()
        sim.terminate()
        sim.wait(10)
        hub.stop()
    print(f"{args.cycles} lockstep cycles over the loopback hub, recording {'on' if args.record else 'off'}, "
          f"load {os.getloadavg()[0]:.1f}: {1e3 * wall / args.cycles:.2f} ms wall per cycle (profiled, "
          f"{0.02 * args.cycles / wall:.1f}x); process CPU per cycle: "
          + ", ".join(f"{name} {1e3 * c / args.cycles:.3f} ms" for name, c in cpu.items()))
    for name in spies:
        counts, total = own_samples(out / f"{name}.txt")
        print(f"\n{name}: {total} on-CPU samples, functions by own samples")
        for func, n in counts.most_common(args.top):
            print(f"  {100 * n / max(total, 1):5.1f} %  {func}")
    shutil.rmtree(out, ignore_errors=True)


def compare_core(args) -> None:
    """The compiled core's saving inside one lockstep run (8 nodes, virtual bus, recording off,
    not profiled): the core on and off every 25 cycles in blocks (on, off, off, on), so both
    see the same machine; the cycle thread's CPU per cycle, medians over the blocks. Both
    states compute the same bits (tests/firmware_sim/test_simcore.py), so switching mid-run
    changes nothing else."""
    import statistics
    from spacearm.firmware_sim import simcore
    core = simcore.core
    if core is None:
        sys.exit("profile_lockstep: the compiled core is not built (or SPACEARM_PURE_PYTHON=1): nothing to compare")
    bus = f"virtual:profile-{time.monotonic_ns()}"
    sim = start_simulator(bus)
    daemon = Daemon(DaemonOptions(bus=bus, clock="lockstep", period=0.02, api=None, record_dir=None))
    on, off, segment = [], [], 25
    try:
        daemon.start()
        daemon.run(max_cycles=50)
        load = os.getloadavg()[0]
        for _ in range(max(1, args.cycles // (4 * segment))):
            cpu = {}
            for state in ("on", "off", "off again", "on again"):
                simcore.core = core if state.startswith("on") else None
                started = time.thread_time()
                daemon.run(max_cycles=segment)
                cpu[state] = (time.thread_time() - started) / segment
            on.append((cpu["on"] + cpu["on again"]) / 2)
            off.append((cpu["off"] + cpu["off again"]) / 2)
    finally:
        simcore.core = core
        daemon.shutdown()
        sim.stop()
    ratios = sorted(a / b for a, b in zip(on, off))
    print(f"{4 * segment * len(on)} lockstep cycles (8 nodes, virtual, recording off), load {load:.1f}-"
          f"{os.getloadavg()[0]:.1f}: cycle thread CPU per cycle, medians of {len(on)} blocks: compiled core "
          f"{1e3 * statistics.median(on):.3f} ms, pure Python {1e3 * statistics.median(off):.3f} ms; core / pure "
          f"{statistics.median(ratios):.3f} (blocks' quartiles {ratios[len(ratios) // 4]:.3f}-"
          f"{ratios[3 * len(ratios) // 4]:.3f})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=1000)
    ap.add_argument("--record", action="store_true", help="record every cycle (MCAP and CAN trace) as the daemon does")
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--transport", default="virtual", choices=["virtual", "loopback"],
                    help="virtual: in-process bus, cProfile; loopback: simulator in its own process, py-spy")
    ap.add_argument("--compare-core", action="store_true",
                    help="no profile: the compiled core on/off every 25 cycles in one run, cycle thread CPU")
    args = ap.parse_args()
    if args.compare_core:
        compare_core(args)
        return
    (profile_loopback if args.transport == "loopback" else profile_in_process)(args)


if __name__ == "__main__":
    main()
