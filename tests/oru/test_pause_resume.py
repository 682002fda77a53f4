"""Pause and resume of the ORU changeout never step the commanded motion: the flow slows to
rest along its path and comes back up to speed within the joint acceleration limits, in a free
motion, the approach's fallback path and an impedance (contact) step alike; the daemon's
pause/resume commands leave events. Scripted arm (it follows its command exactly), no bus."""
from __future__ import annotations

import numpy as np
import pytest

from tests.oru.test_runner_failures import MODEL, Rig, make_runner

PERIOD = 0.02
A_MAX = np.asarray(MODEL.a_max)
V_MAX = np.asarray(MODEL.v_max)


NOISE = np.random.default_rng(7)
OWN_WINDOW = 250     # cycles: about what the pause ramp, 40 still cycles and the resume ramp take


def cycle(rig: Rig) -> np.ndarray:
    """One cycle; the F/T reading carries a little noise as a real sensor's does (a noise-free
    reading held for 25 cycles trips the frozen-sensor check while paused)."""
    return rig.cycle(extra=NOISE.normal(0.0, 0.02, 6)).q.copy()


def run_until(rig: Rig, predicate, history: list[np.ndarray], limit: int = 20000) -> None:
    for _ in range(limit):
        history.append(cycle(rig))
        if predicate():
            return
    raise AssertionError("condition not reached")


def speed(history: list[np.ndarray]) -> float:
    """The last cycle's commanded speed as a fraction of the joint velocity limits."""
    return float(np.max(np.abs(history[-1] - history[-2]) / PERIOD / V_MAX)) if len(history) > 2 else 0.0


def first_step_of(runner, kind: str) -> int:
    names = {"free": lambda s: s.algorithm == "open loop path planning",
             "approach": lambda s: "fallback" in s.algorithm,
             "contact": lambda s: s.algorithm == "impedance control"}
    return next(i for i, s in enumerate(runner.steps) if names[kind](s))


@pytest.mark.parametrize("kind", ["free", "approach", "contact"])
def test_pause_and_resume_stay_within_the_acceleration_limits(kind):
    runner = make_runner()
    rig = Rig(runner)
    target = first_step_of(runner, kind)
    history: list[np.ndarray] = []
    # Run into the chosen step until the arm moves at a good share of its speed (contact steps
    # move slowly: any motion counts).
    threshold = 0.5 if kind != "contact" else 0.01
    run_until(rig, lambda: runner.index == target and runner._begun, history)
    began = len(history)
    run_until(rig, lambda: runner.index > target or speed(history) > threshold, history)
    if kind == "contact":   # long enough in contact to know how the step itself reacts to sensor noise
        run_until(rig, lambda: runner.index > target or len(history) - began >= 300, history)
    assert runner.index == target, "the step finished before it moved"
    before = np.array(history)
    # the step's own accelerations just before the pause, over as many cycles as the pause/resume
    # window below takes (an impedance step reacts to sensor noise with accelerations of its own,
    # 2-3 x the joint limit at 0.02 N, and the worst of such noise grows with the window)
    own = np.diff(before, n=2, axis=0)[-OWN_WINDOW:] / PERIOD ** 2
    own_worst = float(np.max(np.abs(own) / A_MAX)) if len(own) else 0.0
    paused_at = len(history) - 2
    assert runner.pause() == "pausing"        # the daemon calls it inside the cycle; here we are the cycle
    run_until(rig, lambda: runner.state == "paused", history)
    step = runner.steps[runner.index]
    progress = (getattr(step.mode, "travelled", None), getattr(step.mode, "elapsed", None))
    still = [cycle(rig) for _ in range(40)]
    if kind == "contact":
        # paused in contact: the task holds (no insertion progress, its timer stopped) while the
        # admittance keeps regulating the force, so the command moves only with the sensor noise
        assert (step.mode.travelled, step.mode.elapsed) == progress
        drift = float(np.max(np.abs(np.array(still) - still[0])))
        print(f"contact: paused drift {drift:.2e} rad")
        assert drift < 2e-3
    else:
        assert np.allclose(still[0], still[-1])                # paused: holding
    history += still
    assert runner.resume() == "resuming"
    run_until(rig, lambda: runner.state == "running", history)
    history += [cycle(rig) for _ in range(25)]
    assert rig.core.state == "enabled", rig.core.stop_reason   # no protective stop on the way
    q = np.array(history[paused_at:])
    velocity = np.diff(q, axis=0) / PERIOD
    acceleration = np.diff(velocity, axis=0) / PERIOD
    assert np.all(np.abs(velocity) <= V_MAX * 1.001)
    worst = float(np.max(np.abs(acceleration) / A_MAX))
    # Within the limits with margin, or (an impedance step reacting to its sensor) within 1.4 x
    # the step's own noise-driven accelerations just before the pause. In contact the admittance
    # runs on through the pause and only the task's progress ramps (controller/impedance/mode.py):
    # 0.76-1.28 x measured (noise seeds, and where the background planner's delivery puts the
    # noise: it depends on thread timing). Before, the insertion stopped and restarted at full
    # step within one cycle and the admittance froze: 1.5-2.1 x. The jump this also guards
    # against (a 0.1 rad/s step in one cycle) is 250 rad/s^2.
    print(f"{kind}: around pause/resume {worst:.2f} x the limit, the step's own {own_worst:.2f} x")
    assert worst <= max(1.5, 1.4 * own_worst), \
        f"acceleration {worst:.2f} x the limit around pause/resume (the step's own: {own_worst:.2f})"


def test_pause_and_resume_commands_leave_events():
    """Through the daemon's own oru.* commands on a lockstep daemon over the virtual bus."""
    import time
    from tests.daemon.lockstep_daemon import enabled_daemon
    with enabled_daemon("configs/oru/plant_cell.toml", timeout=60) as (daemon, call):
        deadline = time.monotonic() + 60
        call("oru.run", stages=[1])
        time.sleep(0.5)
        assert call("oru.pause") == "pausing"
        while call("oru.status")["state"] != "paused":
            assert time.monotonic() < deadline
            time.sleep(0.02)
        assert call("oru.resume") == "resuming"
        time.sleep(0.2)
        messages = [e["message"] for e in daemon.status()["events"] if e["kind"] == "oru"]
        assert messages == ["pause: ORU changeout pausing", "resume: ORU changeout resuming"]
