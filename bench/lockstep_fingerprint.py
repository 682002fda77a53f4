"""Bit-for-bit fingerprint of scripted lockstep runs: run it on two trees and compare, so a change
that should only make the simulator (or the master) cheaper is shown to compute the same.

    .venv/bin/python bench/lockstep_fingerprint.py --out before.pickle     # on the old tree
    .venv/bin/python bench/lockstep_fingerprint.py --out after.pickle      # on the new tree
    .venv/bin/python bench/lockstep_fingerprint.py --compare before.pickle after.pickle

Each scenario runs a lockstep daemon and simulator cycle by cycle (tests/daemon/lockstep_script.py)
and keeps, per cycle, the recording's /cycle record (without the fields that measure wall-clock
time), the plant's true state after the cycle (every joint's q, qd, motor angle and speed, motor
torque and reported torque, the wrench, the end effector) as exact floats, and every CAN frame
the cycle thread put on the bus (a tap on the channel, in wire order). Heartbeats and the frames
of other threads (the simulator's wall-clock timer, the diagnostics node) follow the wall clock
and are only counted.

The scenarios: "determinism" is test_lockstep_determinism.py's; "cell" drives other joints on the
ORU cell's contact plant with F/T noise and thermal growth, and a drive fault mid-motion (its
fault reaction ramp, the other drives' quick stop); "effects" a plant with every joint effect on
(elastic gear and backlash, feedback latency, Stribeck friction, transmission error, torque
noise and limit, encoder bias, payload error); "rail" the prismatic rail; "panda" the 7-joint
rigid-body plant. Nothing here is a test: it prints where two runs first differ.
"""
from __future__ import annotations

import argparse
import pickle
import sys
import tempfile
import threading
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

WALL_CLOCK_FIELDS = {"period_error", "execution", "io_wait"}

EFFECTS_PLANT = """
seed = 7
[payload]
mass_error = 1.5
com_error = 0.02
[ft]
noise_force = 0.1
noise_torque = 0.005
bias = [0.5, 0.0, -0.2, 0.0, 0.01, 0.0]
[[joints]]
initial_position = 0.0
backlash = 0.002
joint_stiffness = 2.0e4
joint_damping = 300.0
[[joints]]
initial_position = 1.5707963267948966
feedback_latency_cycles = 2
gravity_torque = 60.0
payload_lever = 0.8
[[joints]]
initial_position = -1.5707963267948966
coulomb_friction = 3.0
stribeck_friction = 2.0
viscous_friction = 5.0
[[joints]]
initial_position = 0.0
te_amplitude = 0.0003
te_harmonic = 2.0
te_phase = 0.3
[[joints]]
initial_position = -1.5707963267948966
torque_noise = 0.4
torque_limit = 0.6
[[joints]]
initial_position = 0.0
encoder_bias = 0.0004
resolver_arcsec = 10.0
"""


def plant_state(plant) -> tuple:
    joints = tuple((j.q, j.qd, j.theta, j.thetad, j.motor_torque, j.torque_reported, j.brake_engaged)
                   for j in plant.joints)
    ee = plant.ee
    return joints, tuple(plant.wrench), (ee.grip, ee.turns) if ee is not None else None, plant.time, plant.steps


class Capture:
    """A tap on the bus channel: frames of the cycle thread, in wire order."""

    def __init__(self, bus_spec: str):
        from spacearm.base.transport import open_bus
        self.bus = open_bus(bus_spec)
        self.thread = threading.get_ident()
        self.frames: list[tuple[int, bytes]] = []
        self.other = 0
        self.bus.add_tap(self)

    def on_frame(self, can_id: int, data: bytes, timestamp: float) -> None:
        if threading.get_ident() != self.thread or 0x700 < can_id <= 0x77F:
            self.other += 1
        else:
            self.frames.append((can_id, bytes(data)))

    def on_message_received(self, msg) -> None:
        self.on_frame(msg.arbitration_id, bytes(msg.data), msg.timestamp)

    def on_error(self, exc) -> None:
        raise exc


def run_scenario(name: str, folder: Path) -> dict:
    import uuid
    from spacearm.controller.recording.mcap_reader import read_recording
    from tests.daemon.lockstep_script import scripted_daemon

    plant, arm, bus_config, steps = SCENARIOS[name](folder)
    bus = f"virtual:fp-{name}-{uuid.uuid4().hex[:8]}"
    capture = Capture(bus)
    per_cycle: list[tuple] = []
    state = {}

    def hook():
        per_cycle.append((len(capture.frames), plant_state(state["sim"].plant)))
    kwargs = {"arm": arm} if arm else {}
    if bus_config:
        kwargs["bus_config"] = bus_config
    runs = folder / name
    try:
        with scripted_daemon(plant, record_dir=runs, cycle_hook=hook, bus=bus, enable=False, **kwargs) as script:
            state["sim"] = script.daemon.plant_simulator
            script.call("enable")
            script.run_until(lambda s: s["state"] == "enabled", 500, "enabled")
            steps(script)
            status = script.daemon.status()
            print(f"{name}: ends {status['state']}, stop reason {status['stop_reason']}", flush=True)
    finally:
        capture.bus.shutdown()
    [path] = runs.glob("*.mcap")
    cycles = [{k: v for k, v in m.data.items() if k not in WALL_CLOCK_FIELDS}
              for m in read_recording(path).topic("/cycle")]
    return {"cycles": cycles, "per_cycle": per_cycle, "frames": capture.frames, "other_frames": capture.other}


def _determinism(folder):
    from tests.daemon.test_lockstep_determinism import PLANT, moves
    return PLANT, None, None, moves


def _cell(folder):
    from tests.daemon.test_lockstep_determinism import back_to_work

    def steps(script):
        home = [j["q"] for j in script.daemon.status()["joints"]]
        script.move_and_wait("jog", joint=1, delta=-0.12)
        script.move_and_wait("jog", joint=6, delta=0.3)
        goal = list(home)
        goal[1] += 0.15
        goal[4] -= 0.2
        script.call("move_joints", q=goal)
        script.run(60)
        # a drive faults mid-motion: its fault reaction ramp, the others' quick stop
        script.daemon.plant_simulator.node("joint_3").inject_fault()
        script.run(80)
        back_to_work(script, home, settle=5)
        script.run(15)
    return "configs/plant/oru_cell_errors.toml", None, None, steps


def _effects(folder):
    from tests.daemon.test_lockstep_determinism import back_to_work
    plant = folder / "effects_plant.toml"
    plant.write_text(EFFECTS_PLANT)

    def steps(script):
        home = [j["q"] for j in script.daemon.status()["joints"]]
        script.move_and_wait("move_joints", q=[home[0] + 0.2, home[1] - 0.1, home[2] + 0.15, home[3] - 0.25,
                                               home[4] + 0.1, home[5] + 0.3])
        script.move_and_wait("jog", joint=2, delta=-0.08)
        script.run(10)
        script.call("stop")
        script.run(50)
        back_to_work(script, home)
        script.run(10)
    return plant, None, None, steps


def _rail(folder):
    def steps(script):
        home = [j["q"] for j in script.daemon.status()["joints"]]
        script.move_and_wait("move_joints", q=[0.55] + home[1:3] + [home[3] + 0.1] + home[4:])
        script.run(30)
        script.move_and_wait("move_joints", q=home)
        script.run(10)
    return (ROOT / "configs/plant/oru_testbed_on_rail.toml", ROOT / "configs/arm/oru_testbed_on_rail.toml",
            ROOT / "configs/bus/oru_testbed_on_rail.toml", steps)


def _panda(folder):
    def steps(script):
        home = [j["q"] for j in script.daemon.status()["joints"]]
        goal = list(home)
        goal[1] += 0.4
        goal[3] -= 0.5
        goal[6] += 0.6
        script.move_and_wait("move_joints", q=goal)
        script.call("stop")
        script.run(40)
    return (ROOT / "configs/plant/panda_nominal.toml", ROOT / "configs/arm/panda.toml",
            ROOT / "configs/bus/panda.toml", steps)


SCENARIOS = {"determinism": _determinism, "cell": _cell, "effects": _effects, "rail": _rail, "panda": _panda}


def compare(a: dict, b: dict) -> bool:
    same = True
    for name in a:
        if name not in b:
            print(f"{name}: only in the first")
            continue
        x, y = a[name], b[name]
        problems = []
        if len(x["cycles"]) != len(y["cycles"]):
            problems.append(f"{len(x['cycles'])} vs {len(y['cycles'])} recorded cycles")
        for i, (c, d) in enumerate(zip(x["cycles"], y["cycles"])):
            if repr(c) != repr(d):     # repr: a float's sign of zero too
                problems.append(f"/cycle record {i} differs: " + ", ".join(
                    f"{k}" for k in c if repr(c[k]) != repr(d.get(k))))
                break
        for i, (c, d) in enumerate(zip(x["per_cycle"], y["per_cycle"])):
            if repr(c[1]) != repr(d[1]):
                problems.append(f"plant state after cycle {i} differs")
                break
        frames = [(i, f, g) for i, (f, g) in enumerate(zip(x["frames"], y["frames"])) if f != g]
        if len(x["frames"]) != len(y["frames"]) or frames:
            where = f", first at frame {frames[0][0]}: {frames[0][1]} vs {frames[0][2]}" if frames else ""
            problems.append(f"CAN frames: {len(x['frames'])} vs {len(y['frames'])}{where}")
        if [c[0] for c in x["per_cycle"]] != [c[0] for c in y["per_cycle"]]:
            problems.append("frames per cycle differ")
        status = "DIFFERENT: " + "; ".join(problems) if problems else "identical"
        same &= not problems
        print(f"{name}: {len(x['cycles'])} recorded cycles, {len(x['per_cycle'])} plant states, "
              f"{len(x['frames'])} cycle-thread frames ({x['other_frames']} / {y['other_frames']} heartbeats and "
              f"timer frames not compared): {status}")
    return same


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, help="write the fingerprint here")
    ap.add_argument("--scenarios", default=",".join(SCENARIOS))
    ap.add_argument("--compare", nargs=2, type=Path, metavar=("A", "B"))
    args = ap.parse_args()
    if args.compare:
        a, b = (pickle.loads(p.read_bytes()) for p in args.compare)
        sys.exit(0 if compare(a, b) else 1)
    if args.out is None:
        ap.error("give --out or --compare")
    out = {}
    with tempfile.TemporaryDirectory(prefix="spacearm-fingerprint-") as tmp:
        for name in args.scenarios.split(","):
            if name not in SCENARIOS:
                ap.error(f"no scenario {name!r}: {', '.join(SCENARIOS)}")
            out[name] = run_scenario(name, Path(tmp))
            print(f"{name}: {len(out[name]['cycles'])} cycles, {len(out[name]['frames'])} frames", flush=True)
    args.out.write_bytes(pickle.dumps(out))


if __name__ == "__main__":
    main()
