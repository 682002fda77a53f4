"""The daemon drives the ORU test bed on its linear rail (configs/*/oru_testbed_on_rail.toml)
over the CAN path in one process (virtual bus, lockstep): the rail's drive scaled with its
feed constant, a move of the rail to a target in metres, held, and the recording's q and
tau of the rail in m and N (the force that holds the slide's weight on the plant's ramp)."""
from __future__ import annotations

import pytest

from spacearm.controller.recording.mcap_reader import read_recording
from tests.canopen.test_linear_axis import ARM, BUS, PLANT, RATED_FORCE, rail_hold
from tests.daemon.lockstep_script import scripted_daemon

GOAL = 0.55      # m, from the plant's 0.3 m
STEP = 1.0e-6    # m, the rail's encoder and wire increment
HOLD_CYCLES = 100     # 2 s of controller time at the goal
SETTLE_CYCLES = 10    # 0.2 s: the drive's PD servo settles onto the slide's weight in ~5 cycles


def run_rail_daemon(runs) -> tuple[dict, object]:
    """Move the rail to GOAL and hold it 2 s of controller time, cycle by cycle (no wall clock)."""
    with scripted_daemon(PLANT, arm=ARM, bus_config=BUS, record_dir=runs) as script:
        home = [j["q"] for j in script.daemon.status()["joints"]]
        script.move_and_wait("move_joints", q=[GOAL] + home[1:])
        script.run(HOLD_CYCLES)
        status = script.daemon.status()
        assert status["state"] == "enabled", status["stop_reason"]
    [path] = runs.glob("*.mcap")
    return status, read_recording(path)


def check_rail_recording(cycles: list[dict]) -> None:
    """The rail's recorded q (m) and tau (N): it reached GOAL and held it, pushing up the ramp.
    The hold is judged from the recording alone: from SETTLE_CYCLES after the command reached
    GOAL, whenever the console saw the move end."""
    low, high, stiffness = rail_hold()
    arrived = next(i for i, c in enumerate(cycles)
                   if all(later["q_cmd"][0] == pytest.approx(GOAL, abs=1e-9) for later in cycles[i:]))
    held = cycles[arrived + SETTLE_CYCLES:]
    assert len(held) >= 50
    for c in held:
        assert c["q_cmd"][0] == pytest.approx(GOAL, abs=1e-9)
        droop = GOAL - c["q"][0]
        # PD servo droop under the slide's weight along the ramp +- static friction (0.15..0.18 mm),
        # one encoder step either way; far inside the 5 mm following-error window
        assert low / stiffness - STEP <= droop <= high / stiffness + STEP, droop
        assert low - RATED_FORCE / 1000 <= c["tau"][0] <= high + RATED_FORCE / 1000, c["tau"][0]
    moving = [c for c in cycles[:arrived] if abs(c["dq"][0]) > 0.05]
    assert moving, "the rail never moved faster than 0.05 m/s"
    assert max(c["q"][0] for c in cycles) < GOAL + 0.005        # no overshoot beyond the window


def test_daemon_moves_the_rail_in_metres_and_records_newtons(tmp_path):
    status, recording = run_rail_daemon(tmp_path)
    assert status["arm"] == "oru_testbed_on_rail"
    assert status["joints"][0]["q"] == pytest.approx(GOAL, abs=0.5e-3)
    cycles = [m.data for m in recording.topic("/cycle")]
    check_rail_recording(cycles)


def test_daemon_refuses_a_rail_without_feed_constant_in_one_line(tmp_path):
    from spacearm.base.config.errors import ConfigError
    from spacearm.controller.daemon.daemon import Daemon, DaemonOptions
    with pytest.raises(ConfigError) as info:
        Daemon(DaemonOptions(bus="virtual:unused", arm=ARM, bus_config=BUS.parent / "arm.toml", clock="lockstep",
                             api=None, record_dir=None))
    assert "joint 1 is prismatic" in str(info.value) and "\n" not in str(info.value)
