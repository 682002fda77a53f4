"""ORU changeout benchmark: the paper's stiffness experiment, randomised insertions, and the
full changeout (lockstep wall time, real-time cycle statistics). Prints one table.

    .venv/bin/python bench/bench_oru.py [--trials 200] [--seed 1] [--skip-realtime]

The stiffness experiment and the insertions run the plant and the controller's own contact
code (spacearm.controller.oru.flow's ContactTask in the ImpedanceMode, the drives' servo law) in one
loop without the CAN transport (firmware_sim/contact/direct_loop.py) for speed; the full
changeout runs the daemon and the simulated nodes over the embedded virtual CAN bus.
"""
from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from spacearm.controller.daemon.daemon import Daemon, DaemonOptions  # noqa: E402
from spacearm.offline.scenarios.changeout import run_changeout  # noqa: E402
from spacearm.base.config.bus import DEFAULT_BUS_CONFIG  # noqa: E402
from spacearm.offline.contact.trials import PLANT, ContactTrials, run_stiffness_direct  # noqa: E402
from spacearm.firmware_sim.runner import start_simulator  # noqa: E402


def insertions(trials: ContactTrials, n: int, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    rows = []
    for i in range(n):
        r = math.sqrt(rng.uniform()) * 0.008                       # uniform over the 8 mm disc
        phi = rng.uniform(0, 2 * math.pi)
        axis = rng.uniform(0, 2 * math.pi)
        angle = rng.uniform(0, math.radians(1.5))
        rotvec = (angle * math.cos(axis), angle * math.sin(axis), 0.0)   # tilt about a horizontal axis
        result = trials.run("insert", "airlock_empty", (r * math.cos(phi), r * math.sin(phi)), rotvec)
        rows.append(result)
        print(f"\r  insertion {i + 1}/{n}: {'ok' if result.success else 'FAILED'} "
              f"({1e3 * r:.1f} mm, {math.degrees(angle):.2f} deg)", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    ok = [x for x in rows if x.success]
    return {
        "success": len(ok) / n, "n": n,
        "lateral": np.array([x.peak_lateral_force for x in rows]),
        "torque": np.array([x.peak_torque for x in rows]),
        "insert": np.array([x.peak_insert_force for x in rows]),
        "time": np.array([x.arm_time for x in ok]) if ok else np.array([math.nan]),
        "wall": np.array([x.wall_time for x in rows]),
        "failures": [x.failure for x in rows if not x.success][:3],
    }


def changeout(clock: str, bus_config: str) -> tuple[float, float, dict]:
    bus = f"virtual:bench-oru-{time.monotonic_ns()}"
    sim = start_simulator(bus, bus_config, PLANT)
    daemon = Daemon(DaemonOptions(bus=bus, bus_config=bus_config, clock=clock, api=None, record_dir=None))
    try:
        daemon.start()
        thread = threading.Thread(target=daemon.run, daemon=True)
        thread.start()
        started = time.monotonic()
        result = run_changeout(daemon, lambda name, f: None, sim.plant.environment)
        wall = time.monotonic() - started
        daemon.request_stop()
        thread.join(5)
        return wall, result.arm_time, result.stats
    finally:
        daemon.request_stop()
        daemon.shutdown()
        sim.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=200)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--skip-realtime", action="store_true", help="leave out the real-time changeout (3 min)")
    parser.add_argument("--bus-config", default=str(DEFAULT_BUS_CONFIG),
                        help="bus file of the changeout runs (configs/oru/bus_shared_machine.toml: slower "
                             "heartbeats for an overloaded machine)")
    args = parser.parse_args()
    trials = ContactTrials()
    rows: list[tuple[str, str, str]] = []

    stiff = run_stiffness_direct(trials)
    err = abs(stiff.displacement[0] - stiff.expected)
    rows.append(("stiffness experiment: x displacement at 5 N (K = 1 N/mm)",
                 f"{1e3 * stiff.displacement[0]:.3f} mm (error {1e3 * err:.3f} mm)", "5 mm, error <= 0.2 mm"))
    rows.append(("stiffness experiment: |y|, |z| drift", f"{1e3 * np.max(np.abs(stiff.displacement[1:])):.3f} mm",
                 "< 0.5 mm"))

    ins = insertions(trials, args.trials, args.seed)
    rows.append((f"randomised insertions ({ins['n']}, <= 8 mm, <= 1.5 deg): success",
                 f"{100 * ins['success']:.1f} %", ">= 99 %"))
    rows.append(("  peak lateral force median / max", f"{np.median(ins['lateral']):.2f} / {ins['lateral'].max():.2f} N", "-"))
    rows.append(("  peak torque median / max", f"{np.median(ins['torque']):.3f} / {ins['torque'].max():.3f} N m", "-"))
    rows.append(("  peak insertion force median / max", f"{np.median(ins['insert']):.2f} / {ins['insert'].max():.2f} N",
                 "stop at F_tz = 2.5 N"))
    rows.append(("  time to insert median / max (arm time)", f"{np.median(ins['time']):.2f} / {np.max(ins['time']):.2f} s", "-"))
    rows.append(("  wall time per trial median", f"{np.median(ins['wall']):.2f} s", "-"))

    wall, arm, _ = changeout("lockstep", args.bus_config)
    rows.append(("full changeout, lockstep: wall time", f"{wall:.1f} s ({arm:.1f} s arm time)", "<= 60 s"))
    if not args.skip_realtime:
        wall, arm, stats = changeout("realtime", args.bus_config)
        rows.append(("full changeout, real time: period error median / p99 / max",
                     f"{1e3 * stats['period_error_median']:.3f} / {1e3 * stats['period_error_p99']:.3f} / "
                     f"{1e3 * stats['period_error_max']:.3f} ms", "-"))
        rows.append(("  execution p99 / max; overruns",
                     f"{1e3 * stats['execution_p99']:.3f} / {1e3 * stats.get('execution_max', math.nan):.3f} ms; "
                     f"{stats['overruns']}", "< 20 ms; 0"))

    width = max(len(r[0]) for r in rows)
    print(f"\nbench_oru on {platform.node()} ({platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.1f}), Python {platform.python_version()}")
    print(f"{'figure':<{width}}  {'measured':<34}  target")
    for name, value, target in rows:
        print(f"{name:<{width}}  {value:<34}  {target}")
    for failure in ins["failures"]:
        print(f"insertion failure: {failure}")


if __name__ == "__main__":
    main()
