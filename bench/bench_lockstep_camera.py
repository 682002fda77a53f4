"""Lockstep speed with the camera in the loop: the full changeout on the demo plant with hidden
errors (daemon, simulated nodes and camera over the in-process virtual bus, shared-memory
frame ring), closed-loop approaches on vision. Prints controller (arm) time, wall time, their
ratio (the speed-up over real time), the frames rendered and the wall time the cycle waited for
them, with the load and CPU steal beside.

    .venv/bin/python bench/bench_lockstep_camera.py [--bus-config configs/oru/bus_shared_machine.toml] [--frame-rate 10]

Before the camera ran in controller time the lockstep clock held runs with a camera to <= 4x
real time (frames were rendered in wall time); this bench shows what the run gets now.
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench_oru import CHANGEOUT_BUS, changeout  # noqa: E402
from hil_tests.harness import CpuSteal  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bus-config", default=CHANGEOUT_BUS)
    parser.add_argument("--frame-rate", type=float, default=None, help="Hz of plant time (default: the camera file's)")
    args = parser.parse_args()
    steal, started = CpuSteal(), time.monotonic()
    wall, result, failure, vision_times, daemon = changeout("lockstep", args.bus_config, keep_daemon=True,
                                                           frame_rate=args.frame_rate)
    print(f"\nbench_lockstep_camera on {platform.node()} ({os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}, "
          f"CPU steal {100 * steal.fraction():.1f} %), Python {platform.python_version()}, "
          f"{time.monotonic() - started:.0f} s")
    if result is None:
        print(f"changeout FAILED after {wall:.0f} s: {failure}")
        return
    vision = daemon.vision
    rows = [("full changeout, lockstep, closed-loop approaches: arm time / wall time",
             f"{result.arm_time:.1f} s / {wall:.1f} s"),
            ("  speed-up over real time (arm time / wall time)", f"{result.arm_time / wall:.1f}x"),
            ("  frames measured by the controller", f"{vision.processed}"),
            ("  wall time the cycle waited for rendered frames", f"{getattr(vision, 'wait_time', float('nan')):.1f} s")]
    for s in result.stages:
        rows.append((f"  stage {s.number}: approach frames detected / used", f"{s.detected}/{s.frames}"))
    width = max(len(r[0]) for r in rows)
    for name, value in rows:
        print(f"{name:<{width}}  {value}")


if __name__ == "__main__":
    main()
