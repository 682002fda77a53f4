"""A lockstep run computes the same whatever the machine's speed: the same scripted scenario,
once as fast as it goes and once with the process slowed (a sleep after every cycle, as a
starved or 3x slower machine would run it), gives recordings that agree bit for bit in
everything the arm did. Only the fields that measure wall-clock time itself (period error,
execution, I/O wait) may differ."""
from __future__ import annotations

import time
import uuid

from spacearm.base.transport.line_faults import clear_all, line_fault
from spacearm.controller.recording.mcap_reader import read_recording
from tests.daemon.lockstep_script import scripted_daemon

PLANT = "configs/plant/oru_testbed_errors.toml"    # friction, gravity, D-H errors: a plant with dynamics
WALL_CLOCK_FIELDS = {"period_error", "execution", "io_wait"}


def moves(script) -> None:
    """The scenario's commands on an enabled arm (bench/lockstep_fingerprint.py runs them too)."""
    start = [j["q"] for j in script.daemon.status()["joints"]]
    script.move_and_wait("move_joints", q=[0.3, -0.2, 1.2, -1.3, 0.4, -1.2])
    script.move_and_wait("jog", joint=3, delta=0.05)
    script.run(7)
    script.call("stop")                     # mid-air protective stop, then back to work
    script.run(40)
    back_to_work(script, start)
    script.run(20)


def back_to_work(script, q, settle: int = 0) -> None:
    """After a stop: reset, enable again, and move to q."""
    script.call("reset")
    script.run(settle)
    script.call("enable")
    script.run_until(lambda s: s["state"] == "enabled", 500, "enabled again")
    script.move_and_wait("move_joints", q=q)


def cut_lines_mid_motion(script, lines: tuple[str, str]) -> None:
    """Line A cut mid-motion (the network moves to B), A mended, then B cut mid-motion (back
    to A): the master's line rule and every node's toggle decide at SYNCs."""
    start = [j["q"] for j in script.daemon.status()["joints"]]
    for cut, q in ((lines[0], [0.3, -0.2, 1.2, -1.3, 0.4, -1.2]), (lines[1], start)):
        finished = script.daemon.status()["motions_finished"]
        script.call("move_joints", q=q)
        script.run(25)
        line_fault(cut).set("cut")
        script.run(50)
        line_fault(cut).clear()
        script.run_until(lambda s: s["motions_finished"] > finished, 5000, "end of the move")


def scenario(runs, slow_down: float, stall_at: int | None = None, bus: str | None = None,
             commands=moves) -> tuple[list[dict], list[dict]]:
    """The /cycle and /events records of `commands` run in lockstep. slow_down: s slept after
    every cycle; stall_at: the cycle after which the process stands still for 1 s (a host
    pause, a swap-in), longer than 3 heartbeat periods of any node."""
    cycles = iter(range(10**9))

    def hook():
        n = next(cycles)
        time.sleep(1.0 if n == stall_at else slow_down)
    hook = hook if slow_down or stall_at is not None else None
    with scripted_daemon(PLANT, record_dir=runs, cycle_hook=hook, bus=bus) as script:
        commands(script)
    [path] = runs.glob("*.mcap")
    recording = read_recording(path)
    return ([{k: v for k, v in m.data.items() if k not in WALL_CLOCK_FIELDS} for m in recording.topic("/cycle")],
            [m.data for m in recording.topic("/events")])


def assert_same_cycles(fast: list[dict], slow: list[dict]) -> None:
    assert len(fast) == len(slow) > 200
    for a, b in zip(fast, slow):
        assert a == b, f"cycle {a['cycle']}: " + ", ".join(
            f"{k} {a[k]} != {b.get(k)}" for k in a if a[k] != b.get(k))


def test_a_slowed_lockstep_run_records_the_same_arm_bit_for_bit(tmp_path):
    fast, _ = scenario(tmp_path / "fast", 0.0)
    # +4 ms a cycle (~3x slower than this cycle's own cost), and one 1 s stall mid-motion: in
    # lockstep neither is a lost heartbeat (the stall stops controller and SYNC time alike)
    slow, _ = scenario(tmp_path / "slow", 0.004, stall_at=150)
    assert_same_cycles(fast, slow)


def test_a_slowed_lockstep_run_through_bus_line_cuts_records_the_same_switches_and_arm(tmp_path):
    """A redundant pair's switches used to follow the machine's speed: the master's line rule
    was judged on its timer's wall-clock passes, the nodes toggled on the simulator's timer
    thread, and the controller's wall-clock heartbeat reached SYNC-time consumers at SYNCs
    that depended on how fast the cycles ran (two switches 20 ms apart, the arm's positions
    different from the first cut on)."""
    tag = uuid.uuid4().hex[:8]
    lines = (f"virtual:det-a-{tag}", f"virtual:det-b-{tag}")

    def run(where: str, slow_down: float, stall_at: int | None = None):
        try:
            return scenario(tmp_path / where, slow_down, stall_at, bus="+".join(lines),
                            commands=lambda script: cut_lines_mid_motion(script, lines))
        finally:
            clear_all()
    fast, fast_events = run("fast", 0.0)
    slow, slow_events = run("slow", 0.004, stall_at=120)     # the stall between the two cuts
    switches = [e for e in fast_events if e["kind"].startswith("line_switch")]
    assert [e["kind"] for e in switches] == ["line_switch", "line_switch_complete"] * 2
    # less the nodes' timing notes: they judge heartbeat arrival on the wall clock
    assert [e for e in slow_events if e["kind"] != "nodes"] == [e for e in fast_events if e["kind"] != "nodes"]
    assert_same_cycles(fast, slow)
