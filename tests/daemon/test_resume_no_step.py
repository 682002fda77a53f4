"""Resume of a paused ORU flow sends no velocity the positions do not make (issue 28: on
`oru resume` joint 4 moved 2 mrad in one cycle with its commanded position unchanged, then sat
2.7-3.9 mrad off it): the drives add the velocity offset (60B1h) to their own speed from the
position steps, so an offset with the position standing still pushes the joint off its target
by about 2 zeta v / omega. Judged on every command from the pause to full speed again."""
from __future__ import annotations

import numpy as np

from tests.oru.test_pause_resume import cycle, first_step_of, run_until, speed
from tests.oru.test_runner_failures import MODEL, Rig, make_runner

PERIOD = 0.02
A_MAX = np.asarray(MODEL.a_max)


def test_pause_and_resume_send_no_velocity_the_positions_do_not_make():
    runner = make_runner()
    rig = Rig(runner)
    target = first_step_of(runner, "free")
    history: list[np.ndarray] = []
    run_until(rig, lambda: runner.index == target and runner._begun, history)
    run_until(rig, lambda: speed(history) > 0.5, history)
    commands = []

    def step():
        commands.append(rig.cycle(extra=np.random.default_rng(len(commands)).normal(0.0, 0.02, 6)))

    assert runner.pause() == "pausing"
    while runner.state != "paused":
        step()
    for _ in range(10):
        step()
    assert runner.resume() == "resuming"
    while runner.state != "running":
        step()
    for _ in range(10):
        step()
    q = np.array([c.q for c in commands])
    dq = np.array([c.dq for c in commands])
    steps = np.abs(np.diff(q, axis=0)) / PERIOD               # steps[k]: from command k to k+1
    made = np.maximum(np.vstack([steps[:1], steps]), np.vstack([steps, steps[-1:]]))   # either side of k
    excess = np.abs(dq) - made - A_MAX * PERIOD
    worst = np.unravel_index(np.argmax(excess), excess.shape)
    print(f"worst velocity offset beyond the position steps: {excess[worst]:.4f} rad/s "
          f"(command {worst[0]} of {len(commands)}, joint {worst[1] + 1})")
    assert np.all(excess <= 1e-6), excess[worst]
