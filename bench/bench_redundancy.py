#!/usr/bin/env python3
"""Bus redundancy benchmark (issue 34): line switches and the cost of a second line.

    .venv/bin/python bench/bench_redundancy.py [--trials 5] [--cycles 2000] [--blocks 12] [--processes 3]
        [--transport virtual|loopback]

1. Switch time: the simulator and the master on a redundant pair (in one process on
   virtual lines, or through the loopback hub), cycled at the SYNC period as the daemon's
   real-time loop does (one period's TPDO wait); the active line is cut mid-run, `--trials`
   times (each time the line the network is on). Per trial: time from the cut until the master
   and every node are on the other line (from their own switch events), in node heartbeat
   periods (target <= 3) and in ms; cycles with process data missing; heartbeat-loss and
   both-lines-lost events (target 0); the starvation of the two timers meanwhile.
2. Lockstep cycle cost with two lines vs one (target <= 10 % above): the same enabled network
   cycled `--cycles` times in lockstep (SYNC, wait for every TPDO, read), blocks of one line
   and two lines alternated; CPU and wall per cycle, median of the blocks; the ratio judged is
   the median of the blocks' ratios (each two-line block to the one-line block just before it),
   of the same run. Each setup runs in processes of its own, so a block's process CPU is its
   setup's alone, timer threads included (the pair's redundancy timers, its faster master
   heartbeat), not the idle other setup's; `--processes` of them per setup (default 3), blocks
   rotated over them, since one process running the same code as another can be 15 % off it.
3. Real-time cycle cost, the same way: cycles paced at the SYNC period (as the daemon's
   real-time loop runs them, one period's TPDO wait), `--rt-cycles` per block; CPU per cycle.

    --only cost       the cycle-cost rows alone (2 and 3)
Every row prints the load average and the CPU steal of its measurement.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
import uuid
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hil_tests.harness import CpuSteal  # noqa: E402
from spacearm.base.runtime import priority  # noqa: E402
from spacearm.base.config.bus import load_bus_config  # noqa: E402
from spacearm.base.transport.line_faults import clear_all, line_fault  # noqa: E402
from spacearm.drivers.network import ArmNetwork  # noqa: E402
from spacearm.firmware_sim.runner import Simulator  # noqa: E402

SWITCH_TARGET_PERIODS = 3.0
COST_TARGET = 1.10
FAULT_KINDS = {"heartbeat_lost", "bus_lines_lost", "emcy", "bootup"}


def conditions(steal: CpuSteal) -> str:
    return f"load {os.getloadavg()[0]:.1f}, steal {100 * steal.fraction():.1f} %"


def line_specs(transport: str, hub) -> tuple[str, str]:
    tag = uuid.uuid4().hex[:8]
    if transport == "loopback":
        return hub.spec(f"bench-a-{tag}"), hub.spec(f"bench-b-{tag}")
    return f"virtual:bench-a-{tag}", f"virtual:bench-b-{tag}"


def start(spec: str):
    sim = Simulator(spec, load_bus_config()).start()
    net = ArmNetwork(spec, load_bus_config())
    net.boot()
    net.enable_all()
    return sim, net


def paced(net: ArmNetwork, seconds: float, events: list) -> int:
    """Real-time-like cycles for `seconds`; returns the cycles whose process data was incomplete."""
    period = net.config.bus.sync_period
    incomplete, next_cycle, end = 0, time.monotonic(), time.monotonic() + seconds
    while time.monotonic() < end:
        state = net.cycle(timeout=period)
        incomplete += not state.complete
        events += net.poll_events()
        next_cycle += period
        time.sleep(max(0.0, next_cycle - time.monotonic()))
    return incomplete


def switch_trials(transport: str, trials: int, hub, steal: CpuSteal) -> list[list[str]]:
    lines = line_specs(transport, hub)
    sim, net = start("+".join(lines))
    master, selection = net.line_redundancy, sim.line_selection
    hb = max(n.heartbeat_period for n in net.config.nodes)
    rows = []
    try:
        events: list = []
        paced(net, 0.5, events)
        for trial in range(trials):
            steal.fraction()
            line = master.active
            starved = sim.stats.starved_time + net.stats.starved_time
            events = []
            cut = time.monotonic()
            line_fault(lines[line]).set("cut")
            incomplete = paced(net, 1.0, events)
            starved = sim.stats.starved_time + net.stats.starved_time - starved
            moves = [e.time for e in selection.events if e.kind == "switch" and e.time >= cut]
            moves += [e.time for e in master.events if e.code == "line_switch" and e.time >= cut]
            on_other = master.active == line ^ 1 and all(r.line == line ^ 1 for r in selection.rules.values())
            took = max(moves) - cut if moves and on_other else float("nan")
            faults = sum(e.kind in FAULT_KINDS for e in events)
            ok = on_other and took <= SWITCH_TARGET_PERIODS * hb and faults == 0
            rows.append([f"{transport}: cut line {'AB'[line]} (trial {trial + 1})",
                         f"{took / hb:.2f} hb periods ({1e3 * took:.0f} ms)", f"<= {SWITCH_TARGET_PERIODS:g}",
                         str(incomplete), str(faults), f"{1e3 * starved:.0f} ms", "ok" if ok else "MISSED",
                         conditions(steal)])
            line_fault(lines[line]).clear()
            paced(net, 0.3, [])
    finally:
        net.close()
        sim.stop()
        clear_all()
    return rows


def _cost_worker(spec: str, conn, rt_priority: int) -> None:
    """One setup in its own process at SCHED_FIFO `rt_priority` (as the daemon's real-time loop
    runs; 0: normal), so the controller's 20 ms heartbeat on a pair is not held up behind other
    processes' threads, which its nodes (60 ms consumer time) take for a dead line. Boots, then
    runs the blocks it is sent, answering each with (process CPU s, wall s, line switches so far)
    over its cycles."""
    refused = priority.use_fifo(rt_priority)
    sim, net = start(spec)
    try:
        conn.send(("ready", refused))
        period = net.config.bus.sync_period
        while (job := conn.recv()) is not None:
            paced, cycles = job
            c0, w0 = time.process_time(), time.perf_counter()
            next_cycle = time.monotonic()
            for _ in range(cycles):
                if paced:
                    net.cycle(timeout=period)
                    next_cycle += period
                    time.sleep(max(0.0, next_cycle - time.monotonic()))
                else:
                    net.cycle()
            switches = net.line_redundancy.switches if net.line_redundancy is not None else 0
            conn.send((time.process_time() - c0, time.perf_counter() - w0, switches))
    finally:
        net.close()
        sim.stop()


def cycle_cost(cycles: int, rt_cycles: int, blocks: int, processes: int, rt_priority: int,
               steal: CpuSteal) -> list[list[str]]:
    """Lockstep, then paced cycles on one line and on a pair, alternated in blocks; per-cycle
    CPU and wall. Each setup runs in `processes` processes of its own, block k in the k-th
    (mod `processes`) of each: two processes running the same code differ by up to 15 % in
    CPU per cycle here (issue 34 report), an offset a single process per setup would put into
    every one of its blocks and so into the ratio."""
    import multiprocessing

    context = multiprocessing.get_context("spawn")
    setups: dict[str, list] = {"one line": [], "two lines": []}
    for k in range(processes):
        for name, spec in (("one line", f"virtual:cost-{uuid.uuid4().hex[:8]}"),
                           ("two lines", "+".join(line_specs("virtual", None)))):
            ours, theirs = context.Pipe()
            process = context.Process(target=_cost_worker, args=(spec, theirs, rt_priority), daemon=True)
            process.start()
            setups[name].append((process, ours))
    per_block = cycles // blocks
    rows = []
    try:
        refusals = set()
        for workers in setups.values():
            for _, conn in workers:
                ready, refused = conn.recv()
                if ready != "ready":
                    raise RuntimeError("a cost setup did not start")
                refusals.add(refused)
        scheduling = f"SCHED_FIFO {rt_priority}" if refusals == {None} else "normal: " + "; ".join(map(str, refusals))
        switches = [0] * processes
        for label, paced, n in (("lockstep", False, per_block), ("real-time", True, rt_cycles)):
            cpu = {name: [] for name in setups}
            wall = {name: [] for name in setups}
            steal.fraction()
            for block in range(blocks):
                for name, workers in setups.items():
                    conn = workers[block % processes][1]
                    conn.send((paced, n))
                    used, took, switched = conn.recv()
                    cpu[name].append(used / n)
                    wall[name].append(took / n)
                    if name == "two lines":
                        switches[block % processes] = switched
            rows += cost_rows(label, cpu, wall, processes, conditions(steal))
        rows.append(["line switches in the pair's processes (no fault injected)", f"{sum(switches)}", "0", "", "", "",
                     "ok" if sum(switches) == 0 else "(spurious)", scheduling])
    finally:
        for workers in setups.values():
            for process, conn in workers:
                try:
                    conn.send(None)
                except OSError:
                    pass
                process.join(10)
                if process.is_alive():
                    process.kill()
    return rows


def cost_rows(label: str, cpu: dict, wall: dict, processes: int, where: str) -> list[list[str]]:
    """The ratio judged is the median of the blocks' ratios, each two-line block to the one-line
    block run just before it (a loaded machine's drift cancels in a pair of neighbours); the
    ratio of the two medians is printed beside it, and the spread of the one-line processes'
    own medians (the same code in each: what a process alone is off by)."""
    one, two = statistics.median(cpu["one line"]), statistics.median(cpu["two lines"])
    ratio = statistics.median(b / a for a, b in zip(cpu["one line"], cpu["two lines"]))
    own = [statistics.median(cpu["one line"][k::processes]) for k in range(processes)]
    spread = f"; its {processes} processes' medians {min(own) * 1e6:.0f}-{max(own) * 1e6:.0f} us" if processes > 1 else ""
    return [[f"{label} cycle, one line (reference)",
             f"{1e6 * one:.0f} us CPU / {1e6 * statistics.median(wall['one line']):.0f} us wall{spread}",
             "", "", "", "", "", where],
            [f"{label} cycle, two lines",
             f"{1e6 * two:.0f} us CPU / {1e6 * statistics.median(wall['two lines']):.0f} us wall",
             f"<= {COST_TARGET:.2f} x", f"{ratio:.3f} x (of medians {two / one:.3f} x)", "", "",
             "ok" if ratio <= COST_TARGET else "MISSED", where]]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=5)
    parser.add_argument("--cycles", type=int, default=2000)
    parser.add_argument("--rt-cycles", type=int, default=50, help="paced cycles per block")
    parser.add_argument("--blocks", type=int, default=12)
    parser.add_argument("--processes", type=int, default=3, help="processes per setup, blocks rotated over them")
    parser.add_argument("--rt-priority", type=int, default=50, help="SCHED_FIFO priority of the cost setups (0: normal)")
    parser.add_argument("--only", choices=("cost",), help="the cycle-cost rows alone")
    parser.add_argument("--transport", choices=("virtual", "loopback"), default="virtual")
    args = parser.parse_args()
    steal = CpuSteal()
    hub = None
    if args.transport == "loopback":
        from spacearm.base.transport.hub import HubProcess
        hub = HubProcess(rt_priority=50)
    rows = []
    try:
        if args.only != "cost":
            rows = switch_trials(args.transport, args.trials, hub, steal)
    finally:
        if hub is not None:
            hub.stop()
    rows += cycle_cost(args.cycles, args.rt_cycles, args.blocks, args.processes, args.rt_priority, steal)
    header = ["figure", "measured", "target", "missing cycles / ratio", "fault events", "starved", "", "conditions"]
    widths = [max(len(str(r[i])) for r in rows + [header]) for i in range(len(header))]
    for row in [header] + rows:
        print("  ".join(str(c).ljust(w) for c, w in zip(row, widths)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
