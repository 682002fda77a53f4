"""Run scripted lockstep scenarios in two trees and compare what the daemon recorded and sent,
bit for bit: a check that a speed-up changed nothing the arm does (issue 35). Nothing golden
is kept; both trees run now, on this machine.

    .venv/bin/python scripts/compare_lockstep.py --base /tmp/spacearm-base [--scenario all]

Each run is a fresh process whose `spacearm` package is the given tree (the editable
install's mapping pointed there), cwd that tree. Compared: every /cycle record (less the
wall-clock fields the determinism test leaves out), every /events record (less the nodes'
timing notes, judged on heartbeat arrival times), and the CAN trace
as (line, ID, data, direction) in order, less heartbeats and the simulator's timing reports:
timer threads send those on the wall clock too, so their count and place follow the machine's
speed, not the code (two runs of one tree differ there).
"""
from __future__ import annotations

import argparse
import json
import pickle
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
WALL_CLOCK_FIELDS = {"period_error", "execution", "io_wait"}
WALL_CLOCK_EVENTS = {"nodes"}     # node_timing's heartbeat gaps: heartbeats arrive on the wall clock
SCENARIOS = ("determinism", "pair", "wrist")


def use_tree(root: Path) -> None:
    """Point the editable install's finder (if any) and sys.path at `root`."""
    for module in list(sys.modules.values()):
        mapping = getattr(module, "MAPPING", None)
        if getattr(module, "__name__", "").startswith("__editable__") and isinstance(mapping, dict):
            installed = Path(mapping["spacearm"]).parent
            for key, value in mapping.items():
                mapping[key] = str(root / Path(value).relative_to(installed))
            for key, paths in getattr(module, "NAMESPACES", {}).items():
                module.NAMESPACES[key] = [str(root / Path(p).relative_to(installed)) for p in paths]
    sys.path.insert(0, str(root))


def scenario_pair(script) -> None:
    """A redundant pair: other joints and moves, a Cartesian move, a protective stop mid-jog,
    a disable and a re-enable. No line fault: in trees whose line rule still ran on the master's
    wall-clock timer passes, two runs of one tree already switch a cycle or two apart
    (tests/daemon/test_lockstep_determinism.py runs cuts, slowed and not)."""
    start = [j["q"] for j in script.daemon.status()["joints"]]
    script.move_and_wait("move_joints", q=[0.2, -0.35, 1.0, -1.1, 0.6, -0.8], speed=0.7)
    script.move_and_wait("move_pose", xyz=[0.0, 0.0, 0.02], rpy=[0.0, 0.0, 0.0], frame="tool", speed=0.3)
    script.move_and_wait("jog", joint=6, delta=-0.3, speed=0.5)
    script.call("jog", joint=1, delta=0.4)
    script.run(12)
    script.call("stop")                       # mid-motion protective stop (quick-stop ramp)
    script.run(60)
    script.call("reset")
    script.call("enable")
    script.run_until(lambda s: s["state"] == "enabled", 500, "enabled again")
    script.move_and_wait("move_joints", q=start)
    script.call("disable")
    script.run(30)
    script.call("enable")
    script.run_until(lambda s: s["state"] == "enabled", 500, "enabled after disable")
    script.run(10)


def scenario_wrist(script) -> None:
    """The errors plant, wrist joints and slow moves, a stop while at rest, a jog reversed."""
    start = [j["q"] for j in script.daemon.status()["joints"]]
    script.move_and_wait("move_joints", q=[0.3, -0.2, 1.2, -1.9, 1.1, -0.3], speed=0.4)
    script.move_and_wait("jog", joint=5, delta=-0.2)
    script.move_and_wait("jog", joint=5, delta=0.2, speed=0.3)
    script.call("stop")
    script.run(20)
    script.call("reset")
    script.call("enable")
    script.run_until(lambda s: s["state"] == "enabled", 500, "enabled again")
    script.move_and_wait("move_pose", xyz=[0.0, 0.0, 0.01], rpy=[0.0, 0.0, 0.0], frame="tool", speed=0.3)
    script.move_and_wait("move_joints", q=start)
    script.run(5)


def dump(root: Path, name: str, out: Path) -> None:
    use_tree(root)
    from spacearm.base.transport.line_faults import clear_all
    from spacearm.controller.recording.mcap_reader import read_recording
    from tests.daemon.lockstep_script import scripted_daemon

    runs = Path(tempfile.mkdtemp(prefix=f"cmp-{name}-"))
    stats = {}
    if name == "determinism":      # the test's own scenario, unslowed (its bus name is random)
        from tests.daemon import test_lockstep_determinism

        test_lockstep_determinism.scenario(runs, 0.0)
    else:
        plant = "configs/plant/oru_testbed_nominal.toml" if name == "pair" else "configs/plant/oru_testbed_errors.toml"
        bus = "virtual:cmp-a+virtual:cmp-b" if name == "pair" else "virtual:cmp"
        with scripted_daemon(plant, record_dir=runs, bus=bus) as script:
            (scenario_pair if name == "pair" else scenario_wrist)(script)
            stats = script.daemon.hardware.statistics()
    clear_all()
    from spacearm.base.canopen import peer_timing
    wall_clock_ids = set(peer_timing.SOURCES)
    [path] = runs.glob("*.mcap")
    rec = read_recording(path)
    cycles = [{k: v for k, v in m.data.items() if k not in WALL_CLOCK_FIELDS} for m in rec.topic("/cycle")]
    events = [m.data for m in rec.topic("/events") if m.data.get("kind") not in WALL_CLOCK_EVENTS]
    frames = []
    for line in path.with_suffix(".can.log").read_text().splitlines():
        _stamp, channel, frame, *flags = line.split()
        can_id, _, data = frame.partition("#")
        if not 0x700 <= int(can_id, 16) <= 0x77F and int(can_id, 16) not in wall_clock_ids:
            frames.append((channel if name == "pair" else "", can_id, data, *flags))
    shutil.rmtree(runs, ignore_errors=True)
    out.write_bytes(pickle.dumps({"cycles": cycles, "events": events, "frames": frames,
                                  "stats": {k: stats[k] for k in ("syncs_sent", "tpdos", "expected_tpdos",
                                                                  "syncs_kept_off", "tpdo_timeouts") if k in stats}}))


def compare(a: dict, b: dict) -> list[str]:
    problems = []
    for key in ("cycles", "events", "frames"):
        x, y = a[key], b[key]
        if len(x) != len(y):
            problems.append(f"{key}: {len(x)} vs {len(y)} records")
        for i, (p, q) in enumerate(zip(x, y)):
            if p != q:
                problems.append(f"{key}[{i}] differs: {p!r:.300} vs {q!r:.300}")
                break
    if a["stats"] != b["stats"]:
        problems.append(f"stats: {a['stats']} vs {b['stats']}")
    return problems


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", type=Path, help="the tree to compare with (e.g. a `git archive` of the base commit)")
    ap.add_argument("--new", type=Path, default=HERE)
    ap.add_argument("--scenario", default="all", choices=("all",) + SCENARIOS)
    ap.add_argument("--dump", nargs=2, metavar=("SCENARIO", "OUT"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.dump:
        dump(args.new.resolve(), args.dump[0], Path(args.dump[1]))
        return
    failed = False
    for name in SCENARIOS if args.scenario == "all" else (args.scenario,):
        results = {}
        for label, root in (("base", args.base), ("new", args.new)):
            out = Path(tempfile.mkstemp(prefix=f"cmp-{name}-{label}-", suffix=".pkl")[1])
            subprocess.run([sys.executable, str(Path(__file__).resolve()), "--new", str(root.resolve()),
                            "--dump", name, str(out)], cwd=root, check=True)
            results[label] = pickle.loads(out.read_bytes())
        problems = compare(results["base"], results["new"])
        r = results["new"]
        print(json.dumps({"scenario": name, "cycles": len(r["cycles"]), "events": len(r["events"]),
                          "frames": len(r["frames"]), "stats": r["stats"],
                          "identical": not problems}))
        for p in problems:
            print("  " + p)
        failed |= bool(problems)
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
