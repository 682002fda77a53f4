"""The ORU test bed on its linear rail with the daemon and `spacearm sim` as separate
processes on the loopback CAN hub: the rail's drive booted with its feed constant (6092h),
the rail moved by the console to a target in metres and held, the recording's rail q/tau in
m and N (see tests/daemon/test_rail_daemon.py for what the numbers must be and why)."""
from __future__ import annotations

import json
import os
import time

import pytest

from hil_tests.harness import free_port
from hil_tests.test_daemon_console import Console
from spacearm.controller.recording.mcap_reader import read_recording
from tests.canopen.test_linear_axis import ARM, BUS, PLANT
from tests.daemon.test_rail_daemon import GOAL, check_rail_recording

pytestmark = pytest.mark.hil


def test_rail_moves_and_holds_over_the_loopback_hub(loopback_hub, launch, tmp_path):
    bus = loopback_hub.spec(f"rail-{os.getpid()}-{time.monotonic_ns()}")
    launch(["-m", "spacearm.console.main", "sim", "--plant", str(PLANT), "--bus-config", str(BUS), "--time-base", "sync"],
           bus_spec=bus, ready="nodes ready")
    api = f"tcp:127.0.0.1:{free_port()}"
    launch(["-m", "spacearm.console.main", "daemon", "--clock", "lockstep", "--api", api, "--arm", str(ARM),
            "--bus-config", str(BUS), "--record-dir", str(tmp_path / "runs")], bus_spec=bus,
           ready="spacearm daemon:", timeout=30)
    console = Console(api, tmp_path / "lease")
    status = console.status()
    assert status["arm"] == "oru_testbed_on_rail"
    bringup = status["bringup"]
    assert bringup["joint_1"]["sdo_writes"] == bringup["joint_2"]["sdo_writes"] + 2     # and 6092h.1/.2
    console.run("enable")
    deadline = time.monotonic() + 60
    while console.status()["state"] != "enabled":
        assert time.monotonic() < deadline
        time.sleep(0.05)
    home = [j["q"] for j in console.status()["joints"]]
    moved = json.loads(console.run("move", "joints", repr(GOAL), *map(repr, home[1:]), "--json").stdout)
    assert moved["final"]["state"] == "enabled"
    held_from = console.status()["cycle"]
    while console.status()["cycle"] < held_from + 100:          # hold 2 s of controller time
        assert time.monotonic() < deadline + 60
        time.sleep(0.05)
    status = console.status()
    assert status["joints"][0]["q"] == pytest.approx(GOAL, abs=0.5e-3)
    stopped = json.loads(console.run("record", "stop", "--json").stdout)
    recording = read_recording(stopped["path"])
    check_rail_recording([m.data for m in recording.topic("/cycle")])
