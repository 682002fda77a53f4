"""Lockstep cycle cost with the arm enabled and moving, beside the same arm at rest (issue 35).

    .venv/bin/python bench/bench_moving_arm.py [--cycles 2000] [--rounds 3]

bench_daemon.py's lockstep rows run an arm that is never enabled: every drive holds its brake,
and a rigid-body plant whose joints are all held skips its dynamics (Plant.step). What a
campaign or a diagnosis replay pays is the moving arm: drives enabled in CSP, the planner's
set-points, the servo and the plant's sub-steps every period. Here each arm is enabled and
moves back and forth between two joint goals (`move_joints`, the daemon's own planner) for
`--cycles` cycles, and, in the same round, runs as many cycles unenabled.

Cost per cycle = this process's CPU per cycle (the daemon's cycle, the in-process simulator's
SYNC handling, the recorder's and timer threads: everything the cycles make this process do)
as % of the reference loop's CPU timed in the same run (bench/reference_work.py), median over
rounds. The motions are planned on the API thread between two cycles; that planning is not
counted (the cycles are timed from the first cycle after the request was taken).
Recording is on, as the daemon runs by default.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.reference_work import reference_loop_seconds  # noqa: E402
from hil_tests.harness import CpuSteal  # noqa: E402
from tests.daemon.lockstep_script import scripted_daemon  # noqa: E402

ARMS = {   # name: (plant, arm, bus config, offsets of the second goal from home, rad)
    "ORU test bed, 6 joints": ("configs/plant/oru_testbed_nominal.toml", None, "configs/bus/arm.toml",
                               (0.25, -0.2, 0.2, -0.3, 0.25, 0.4)),
    "Panda rigid body, 7 joints": ("configs/plant/panda_nominal.toml", "configs/arm/panda.toml",
                                   "configs/bus/panda.toml", (0.3, 0.4, -0.3, -0.5, 0.3, 0.4, 0.6)),
}


def _stack(arm: tuple, records: Path, enable: bool):
    plant, arm_file, bus, _ = arm
    return scripted_daemon(ROOT / plant, arm=arm_file and ROOT / arm_file, bus_config=ROOT / bus,
                           record_dir=records, enable=enable)


def moving_cost(arm: tuple, cycles: int, records: Path) -> tuple[float, float]:
    """(CPU s per cycle while moving, share of those cycles with a motion running)."""
    with _stack(arm, records, enable=True) as script:
        home = [j["q"] for j in script.daemon.status()["joints"]]
        goals = [[q + d for q, d in zip(home, arm[3])], home]
        cpu, counted, moving = 0.0, 0, 0
        core = script.daemon.core     # its counter, not status(): building a status is no part of a cycle
        while counted < cycles:
            finished = core.motions_finished
            script.call("move_joints", q=goals[0])
            goals.reverse()
            started = time.process_time()
            while counted < cycles:
                script.daemon.cycle_once()
                counted += 1
                if core.motions_finished > finished:
                    break
                moving += 1
            cpu += time.process_time() - started
        return cpu / counted, moving / counted


def resting_cost(arm: tuple, cycles: int, records: Path) -> float:
    with _stack(arm, records, enable=False) as script:
        script.run(50)      # first calls, not measured
        started = time.process_time()
        script.run(cycles)
        return (time.process_time() - started) / cycles


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=2000, help="cycles per arm, state and round")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    steal, loads = CpuSteal(), [os.getloadavg()[0]]
    reference = [reference_loop_seconds()[1]]
    rows: dict[str, dict[str, list[float]]] = {name: {"moving": [], "resting": [], "share": []} for name in ARMS}
    with tempfile.TemporaryDirectory(prefix="spacearm-bench-moving-") as folder:
        for k in range(args.rounds):
            for i, (name, arm) in enumerate(ARMS.items()):
                records = Path(folder) / f"{k}-{i}"
                per_cycle, share = moving_cost(arm, args.cycles, records / "moving")
                rows[name]["moving"].append(per_cycle)
                rows[name]["share"].append(share)
                rows[name]["resting"].append(resting_cost(arm, args.cycles, records / "resting"))
            loads.append(os.getloadavg()[0])
    reference.append(reference_loop_seconds()[1])
    ref = statistics.median(reference)
    print(f"reference loop {1e3 * ref:.0f} ms CPU (median of the timings before and after); "
          f"load {min(loads):.1f}-{max(loads):.1f}, host steal {100 * steal.fraction():.1f} %; "
          f"{args.rounds} rounds x {args.cycles} cycles, Python {sys.version.split()[0]}, "
          f"{'pure Python' if os.environ.get('SPACEARM_PURE_PYTHON') == '1' else 'compiled core if built'}")
    print(f"| arm | resting: % of reference (ms CPU/cycle) | moving: % of reference (ms CPU/cycle) | "
          f"moving / resting | cycles with a motion running |")
    print("|---|---|---|---|---|")
    for name, r in rows.items():
        rest, move = statistics.median(r["resting"]), statistics.median(r["moving"])
        print(f"| {name} | {100 * rest / ref:.3f} % ({1e3 * rest:.3f}) | {100 * move / ref:.3f} % ({1e3 * move:.3f}) | "
              f"{move / rest:.2f}x | {100 * statistics.median(r['share']):.0f} % |")


if __name__ == "__main__":
    main()
