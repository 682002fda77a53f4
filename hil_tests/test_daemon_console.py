"""Daemon and simulator as separate processes on the loopback CAN hub, driven by the real
`spacearm` console commands: every command end to end, control lease, bad commands cause no
motion, protective stop on a device fault, recording complete and readable after kill -9."""
from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from spacearm.controller.recording.csv_export import export_csv
from spacearm.controller.recording.mcap_reader import read_recording
from hil_tests.conftest import ROOT, child_env
from hil_tests.harness import free_port
from hil_tests.vm.runner import descendants

pytestmark = pytest.mark.hil
READY = [-0.28806419791259463, 1.5707963267948966, -3.294079780986511, 1.9521648103310305,
         -0.22888135613941607, 1.2827321288823015]


class Console:
    """One operator: its own lease store, talking to the daemon through `spacearm`."""

    def __init__(self, api: str, lease_dir: Path):
        self.api = api
        self.env = child_env({"SPACEARM_LEASE_DIR": str(lease_dir)})

    def run(self, *args: str, check: bool = True) -> subprocess.CompletedProcess:
        result = subprocess.run([sys.executable, "-m", "spacearm.console.main", *args, "--api", self.api],
                                capture_output=True, text=True, cwd=ROOT, env=self.env, timeout=120)
        if check and result.returncode != 0:
            raise AssertionError(f"spacearm {' '.join(args)} failed: {result.stdout}{result.stderr}")
        return result

    def status(self) -> dict:
        return json.loads(self.run("status", "--json").stdout)


@pytest.fixture
def stack(loopback_hub, launch, tmp_path):
    bus = loopback_hub.spec(f"daemon-{os.getpid()}-{time.monotonic_ns()}")
    launch(["-m", "spacearm.console.main", "sim", "--plant", "configs/plant/oru_testbed_nominal.toml",
            "--control-node", "126", "--rt-priority", "50", "--time-base", "sync"], bus_spec=bus, ready="nodes ready")   # as the README runs it
    api = f"tcp:127.0.0.1:{free_port()}"
    daemon = launch(["-m", "spacearm.console.main", "daemon", "--clock", "lockstep", "--api", api,
                     "--record-dir", str(tmp_path / "runs")], bus_spec=bus, ready="spacearm daemon:", timeout=30)
    return {"bus": bus, "api": api, "daemon": daemon, "runs": tmp_path / "runs",
            "alice": Console(api, tmp_path / "alice"), "bob": Console(api, tmp_path / "bob")}


RESOLVER_QUANTUM = math.radians(25 / 3600)


def joints(status: dict) -> list[float]:
    return [j["q"] for j in status["joints"]]


def targets(status: dict) -> list[float]:
    return [j["q_cmd"] for j in status["joints"]]


def test_console_commands_end_to_end(stack):
    alice, bob = stack["alice"], stack["bob"]
    status = alice.status()
    assert status["state"] == "disabled" and status["clock"] == "lockstep"
    assert "state disabled" in alice.run("status").stdout          # human-readable view
    assert alice.run("enable").stdout.strip() == "enable: arm is enabled"     # waits for the drives
    for _ in range(100):
        if alice.status()["state"] == "enabled":
            break
        time.sleep(0.05)
    assert alice.status()["state"] == "enabled"

    alice.run("move", "joints", *map(str, READY))
    assert joints(alice.status()) == pytest.approx(READY, abs=2e-3)
    before = joints(alice.status())
    alice.run("jog", "6", "-5deg")
    after = joints(alice.status())
    assert after[5] - before[5] == pytest.approx(-math.radians(5), abs=2e-3)
    moved = json.loads(alice.run("move", "pose", "0", "0", "20mm", "0", "0", "0", "--frame", "tool",
                                 "--json").stdout)
    assert moved["mode"] == "move_pose" and moved["final"]["state"] == "enabled"

    # A second console may watch but not move the arm; its refused commands cause no motion.
    held, held_targets = joints(status := bob.status()), targets(status)
    refused = bob.run("jog", "1", "10deg", check=False)
    assert refused.returncode == 1 and refused.stderr.startswith("error[lease_held]:")
    assert bob.run("control", "take", check=False).returncode == 1
    # Bad commands from the controlling console: clear one-line errors, no motion.
    for args, code, message in ((["jog", "9", "1deg"], "bad_argument", "not a joint"),
                                (["jog", "1", "2rad"], "bad_argument", "out of range"),
                                (["move", "joints", "0", "0"], "bad_argument", "expected 6 joint values"),
                                (["move", "pose", "5", "0", "0", "0", "0", "0"], "planning_refused", "beyond the arm's reach"),
                                (["jog", "1", "ten"], None, "is not an angle")):   # refused by the console itself
        bad = alice.run(*args, check=False)
        assert bad.returncode != 0 and message in bad.stderr, (args, bad.stderr)
        assert code is None or bad.stderr.startswith(f"error[{code}]:"), (args, bad.stderr)
        assert "Traceback" not in bad.stderr
    status = alice.status()
    assert targets(status) == held_targets            # nothing new was commanded
    assert joints(status) == pytest.approx(held, abs=2 * RESOLVER_QUANTUM)

    # Anyone may stop; motion then needs an explicit reset (and enable).
    assert "stopped" in bob.run("stop").stdout
    status = alice.status()
    assert status["state"] == "stopped" and status["stop"]["code"] == "operator_stop"
    assert alice.run("jog", "1", "1deg", check=False).stderr.startswith("error[protective_stop]:")
    alice.run("reset")
    assert alice.status()["state"] == "disabled"

    stopped = json.loads(alice.run("record", "stop", "--json").stdout)
    recording = read_recording(stopped["path"])
    cycles = [m.data["cycle"] for m in recording.topic("/cycle")]
    assert recording.complete and cycles == list(range(cycles[0], cycles[0] + len(cycles)))
    kinds = {m.data["kind"] for m in recording.topic("/events")}
    assert {"protective_stop", "reset", "motion"} <= kinds
    assert Path(stopped["can_log"]).stat().st_size > 0


def test_device_fault_causes_protective_stop_with_reason(stack):
    from spacearm.drivers.network import ArmNetwork  # noqa: F401  (SimControl needs a network handle)
    alice = stack["alice"]
    alice.run("enable")
    time.sleep(0.5)
    # Silence joint 4 through the simulator's test-rig node, over the same bus.
    probe = subprocess.run([sys.executable, "-c", f"""
from spacearm.drivers.network import ArmNetwork
from spacearm.drivers.sim_control import SimControl
net = ArmNetwork({stack['bus']!r}).connect()
SimControl(net).silence('joint_4')
net.close()
"""], capture_output=True, text=True, cwd=ROOT, env=child_env(), timeout=60)
    assert probe.returncode == 0, probe.stderr
    for _ in range(100):
        status = alice.status()
        if status["state"] == "stopped":
            break
        time.sleep(0.05)
    assert status["state"] == "stopped"
    assert "joint_4" in (status["stop"]["node"], status["stop"]["joint"]), status["stop"]
    assert alice.run("enable", check=False).stderr.startswith("error[protective_stop]:")


def cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def alive(pid: int) -> bool:
    """Running, not a zombie waiting for its (re-)parent to reap it."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_recording_is_readable_after_kill_9(stack):
    alice = stack["alice"]
    alice.run("enable")
    alice.run("move", "joints", *map(str, READY), "--no-wait")
    time.sleep(2.0)
    path = alice.status()["recording"]["path"]
    writers = [pid for pid in descendants(stack["daemon"].pid) if "writer_process" in cmdline(pid)]
    assert writers, "the daemon runs no recording writer"
    os.killpg(stack["daemon"].pid, signal.SIGKILL)
    stack["daemon"].wait(10)
    # The writer has its own session so it outlives the kill and drains what the daemon handed
    # over; read the file once it has ended, or a second read sees more cycles than the first.
    deadline = time.monotonic() + 60
    while any(alive(pid) for pid in writers):
        assert time.monotonic() < deadline, "the recording writer did not end after its daemon died"
        time.sleep(0.05)
    recording = read_recording(path)
    assert not recording.complete
    cycles = [m.data["cycle"] for m in recording.topic("/cycle")]
    assert len(cycles) > 50
    assert cycles == list(range(cycles[0], cycles[0] + len(cycles)))  # every SYNC present, no gaps
    result = export_csv(path, Path(path).with_suffix(".csv"))
    assert result.rows == len(cycles) and result.gaps == [] and not result.complete
