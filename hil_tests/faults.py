"""Fault-injection helpers for the reliability suite (hil_tests/test_faults_*.py, bench/bench_reliability.py).

The daemon (real-time clock, 20 ms) and the simulator run as separate processes on a loopback
hub in a third one that the test steers (hil_tests/faulty_hub.py), so the test can also lose,
reorder or cut frames on the "bus" itself. Faults inside devices go through the simulator's fault-injection node 126
(drivers/sim_control.py). Time to safe state is measured from just before the injecting
call to the first status poll (every ~5 ms on a held API connection) that shows the
protective stop, and to the first that shows every drive out of "operation enabled" and
every joint at rest (quick-stop ramp done, brakes on); 1 cycle = 20 ms.

Expected reaction to each fault (bound = what the tests assert; measured: bench_reliability):

| fault | injected by | detected as (stop reason code) | bound to stop |
| --- | --- | --- | --- |
| node heartbeat stops | rig.stop_heartbeat | heartbeat_lost (2.5 heartbeat periods = 250 ms) | 20 cycles |
| node silent / bus-off | rig.silence | pdo_missing (5 cycles) or heartbeat_lost | 12 cycles |
| node restarts | rig.power_cycle | bootup (unexpected boot-up) | 10 cycles |
| EMCY / drive fault | rig.raise_fault | emcy, fault | 10 cycles |
| simulator killed mid-motion | SIGKILL | pdo_missing / heartbeat_lost | 12 cycles |
| bus blackout (all frames lost) | hub filter | pdo_missing | 12 cycles |
| random frame loss 2 %, reordering 2 % | hub filter | tolerated: no stop, motion completes (frames counted) | - |
| daemon's connection cut, back at once | hub disconnect | tolerated if back within 5 cycles, else pdo_missing | - |
| joint stall mid-motion | rig.stall | following_error (1 deg) | 25 cycles |
| joint limit hit | plant starts beyond the limit | position_limit (on enable) | 10 cycles |
| F/T overload | rig.set_wrench 400 N | ft_overload (sensor flag) / emcy | 10 cycles |
| F/T jump | rig.set_wrench step 100 N | ft_jump (80 N in one cycle) | 10 cycles |
| F/T frozen | rig.freeze | ft_frozen (25 identical readings once live) | 40 cycles |
| jogging console vanishes | close its connection | command_watchdog | 10 cycles |
| jogging console silent | no request for 1 s | command_watchdog (1.0 s keep-alive) | 1 s + 10 cycles |
| daemon killed mid-motion | SIGKILL | drives: controller heartbeat lost -> quick stop, brakes; restart: disabled | - |
| laser ranger timeout / garbage | ranger sim drop/garble | RangerError after retries (bounded time); the routine stops | - |

After every stop: no motion (positions hold within a resolver step), motion commands are
refused until `reset`, and the reason is in `status` and in the recording's /events.
Missing data while the host held a vCPU (base/runtime/host_cpus.py) is waited out for up to
HOST_CYCLES_EXCUSED cycles before it counts: a test whose stop came in such a stall allows them.
Camera faults mid-approach run at the controller core (test_faults_camera.py: marker lost ->
vision_lost after 6 frames; no frames -> vision_lost after 10 s). Brake loss is not covered.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from spacearm.console.client import ApiClient
from spacearm.base.runtime.child_process import module_env
from spacearm.controller.daemon.supervision import HOST_CYCLES_EXCUSED
from hil_tests.harness import StealTimeline, free_port

ROOT = Path(__file__).resolve().parents[1]
# The daemon's cycle. (Tried 50 ms to give an overloaded machine room: full-speed CSP moves
# then read 25 % above v_max at the drive and trip the velocity check, so 20 ms it stays.)
PERIOD = 0.02
NOMINAL_PLANT = ROOT / "configs/plant/oru_testbed_nominal.toml"
READY = [-0.28806419791259463, 1.5707963267948966, -3.294079780986511, 1.9521648103310305,
         -0.22888135613941607, 1.2827321288823015]
RESOLVER_STEP = np.radians(25 / 3600)
HOME = [0.0, np.pi / 2, -np.pi / 2, 0.0, -np.pi / 2, 0.0]   # where the nominal plant starts
RESULTS_ENV = "SPACEARM_FAULT_RESULTS"   # JSON-lines file the tests append measurements to


def child_env() -> dict:
    return {**module_env(), "PYTHONUNBUFFERED": "1"}


# ------------------------------------------------------------------------ the stack
@dataclass
class Stack:
    """Simulator + daemon processes on one bus; `client` holds the control lease."""
    bus: str
    channel: str
    api: str
    workdir: Path
    plant: Path
    sim: subprocess.Popen | None = None
    daemon: subprocess.Popen | None = None
    client: ApiClient | None = None
    lease: str | None = None
    procs: list = field(default_factory=list)
    # per-vCPU steal while the stack lives: a stop for silent nodes is judged against it
    steal: StealTimeline = field(default_factory=StealTimeline)
    _rig: object = None
    _net: object = None

    # -- processes
    def _spawn(self, args: list[str], name: str, ready: str, timeout: float) -> subprocess.Popen:
        log = self.workdir / f"{name}{len(self.procs)}.log"
        out = open(log, "w")
        proc = subprocess.Popen([sys.executable, "-m", "spacearm.console.main", *args, "--bus", self.bus],
                                stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                cwd=str(ROOT), env=child_env(), start_new_session=True)
        out.close()
        self.procs.append(proc)
        deadline = time.monotonic() + timeout
        while ready not in log.read_text(errors="replace"):
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"{name} did not get ready: {log.read_text(errors='replace')[-3000:]}")
            time.sleep(0.05)
        return proc

    def start_sim(self, *extra: str) -> None:
        # The simulated hardware at real-time priority like the daemon (base/runtime/priority.py), so
        # the reaction times measured are the controller's, not this machine's other load.
        self.sim = self._spawn(["sim", "--plant", str(self.plant), "--control-node", "126", "--rt-priority", "50",
                                *extra], "sim", "nodes ready", 60)

    def start_daemon(self) -> None:
        self.daemon = self._spawn(["daemon", "--clock", "realtime", "--period", str(PERIOD), "--api", self.api,
                                   "--record-dir", str(self.workdir / "runs")],
                                  "daemon", "spacearm daemon:", 60)
        self.client = ApiClient(self.api, timeout=10.0)
        self.lease = self.client.call("control.take", holder="fault-suite")["lease"]

    def call(self, cmd: str, **args):
        return self.client.call(cmd, lease=self.lease, **args)

    def status(self) -> dict:
        return self.client.call("status")

    @property
    def rig(self):
        """The simulator's fault-injection node, over the same bus."""
        if self._rig is None:
            from spacearm.drivers.network import ArmNetwork
            from spacearm.drivers.sim_control import SimControl
            from spacearm.base.config.bus import load_bus_config, DEFAULT_BUS_CONFIG
            config = load_bus_config(DEFAULT_BUS_CONFIG)
            # No controller heartbeat from the test: the drives must notice a killed daemon.
            # Its SDO reads are the test's look at the drives, not a device's timing: a daemon
            # cycling flat out beside them on a loaded machine (CI at load 9) kept three reads
            # of 0.5 s each unanswered, so they wait as long as the fault-injection unit does.
            config = config.model_copy(update={"bus": config.bus.model_copy(
                update={"master_heartbeat_period": 0.0, "sdo_timeout": 10.0})})
            self._net = ArmNetwork(self.bus, config).connect()
            self._rig = SimControl(self._net)
        return self._rig

    def kill(self, proc: subprocess.Popen, sig: int = 9) -> None:
        if proc is not None and proc.poll() is None:
            try:
                os.killpg(proc.pid, sig)
            except ProcessLookupError:
                pass
            proc.wait(10)

    def close(self) -> None:
        self.steal.stop()
        if self.client is not None:
            try:
                self.client.close()
            except Exception:
                pass
        if self._net is not None:
            self._net.close()
        for proc in self.procs:
            if proc.poll() is None:
                try:
                    os.killpg(proc.pid, 15)
                except ProcessLookupError:
                    continue
        for proc in self.procs:
            try:
                proc.wait(5)
            except subprocess.TimeoutExpired:
                self.kill(proc)

    # -- operator actions
    def enable(self, timeout: float = 10.0) -> None:
        status = self.status()
        if status["state"] == "stopped" or any(j["fault"] for j in status["joints"]):
            self.recover()
        self.call("enable")
        wait_for(lambda: self.status()["state"] == "enabled", timeout,
                 lambda: f"arm enabled (state {(s := self.status())['state']}, {s['stop_reason']}, "
                         f"events {s['events'][-4:]})")

    def recover(self) -> None:
        """After a stop: reset (drive faults cleared by the daemon), back to disabled. A reset
        is refused busy while the planned stop still brings the arm to rest: wait for that."""
        from spacearm.console.errors import CommandFailed
        deadline = time.monotonic() + 30.0
        while True:
            try:
                self.call("reset")
                break
            except CommandFailed as exc:
                if exc.code != "busy" or time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        if self.status()["state"] == "stopped":   # stopped again while the drives were resetting
            time.sleep(0.3)
            self.call("reset")
        wait_for(lambda: (s := self.status())["state"] == "disabled" and not any(j["fault"] for j in s["joints"]),
                 5.0, lambda: f"disabled, drive faults cleared after reset (state {(s := self.status())['state']}, "
                              f"{s['stop_reason']}, events {s['events'][-4:]})")

    def move(self, q, speed: float = 1.0) -> dict:
        return self.call("move_joints", q=list(map(float, q)), speed=speed)

    def enable_and_hold(self, seconds: float) -> None:
        """Enable and hold for `seconds` without any stop: a stop here, before any fault is
        injected, fails the test with its code and reason (no retry hides it)."""
        self.enable()
        time.sleep(seconds)
        status = self.status()
        if status["state"] != "enabled":
            raise AssertionError(f"stopped while holding [{(status['stop'] or {}).get('code')}]: "
                                 f"{status['stop_reason']}")

    def far_target(self) -> list[float]:
        """HOME or READY, whichever is farther from here (a move of a few seconds)."""
        q = np.array([j["q"] for j in self.status()["joints"]])
        return READY if np.abs(q - HOME).max() < np.abs(q - READY).max() else HOME

    def wait_motion(self, motion: int, timeout: float = 30.0) -> dict:
        def done():
            s = self.status()
            if s["state"] == "stopped":
                raise AssertionError(f"protective stop during motion: {s['stop_reason']}")
            return s["motions_finished"] >= motion
        wait_for(done, timeout, f"motion {motion} finished")
        return self.status()


def start_stack(hub, workdir: Path, plant: Path = NOMINAL_PLANT, name: str | None = None,
                rig: bool = True) -> Stack:
    """Simulator and daemon on `hub` (a FaultyHub, or any hub with .spec(name))."""
    channel = name or f"faults-{os.getpid()}-{time.monotonic_ns()}"
    workdir.mkdir(parents=True, exist_ok=True)
    stack = Stack(hub.spec(channel), channel, f"tcp:127.0.0.1:{free_port()}", workdir, plant)
    try:
        stack.start_sim()
        # Connect the rig before the daemon runs: loading its object dictionaries holds this
        # process's GIL, and an in-process hub (any hub with .spec) would stall meanwhile.
        if rig:
            stack.rig
        stack.start_daemon()
    except Exception:
        stack.close()
        raise
    return stack


def wait_for(predicate, timeout: float, what: str, poll: float = 0.02) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:.1f} s waiting for: "
                                 f"{what() if callable(what) else what}")
        time.sleep(poll)


# ------------------------------------------------------------------------ measuring
@dataclass
class SafeState:
    fault: str
    reason: str
    code_seen: str
    to_stop: float        # s from injection to the stop shown in status
    to_rest: float        # s from injection to every drive disabled and every joint at rest (quick-stop ramp done)
    status: dict
    executed_cycles: int  # control cycles run from the first poll after injection to the stop
    host_stalled_cycles: int = 0   # of them, cycles whose missing data came while the host held a vCPU

    @property
    def stop_cycles(self) -> float:
        """Cycles to the stop: the executed ones (what the supervision bounds are about); on a
        loaded machine overruns make the wall time longer than cycles x 20 ms."""
        return float(self.executed_cycles)

    def assert_stopped_within(self, bound_cycles: float) -> None:
        """The fault table's bound; a vCPU held by the host during the silence adds what the
        supervision waits out of a stall (supervision.HOST_CYCLES_EXCUSED)."""
        bound = bound_cycles + (HOST_CYCLES_EXCUSED if self.host_stalled_cycles else 0)
        assert self.stop_cycles <= bound, (f"{self.fault}: {self.stop_cycles:.1f} cycles > {bound} "
                                           f"({self.host_stalled_cycles} cycles in a host stall)")


def wait_safe(stack: Stack, t0: float, fault: str, timeout: float = 5.0, brakes: bool = True) -> SafeState:
    """Poll status (~5 ms) until the stop shows, then until every drive is disabled (unless
    `brakes` is False: nothing answers once the simulator is gone)."""
    watcher = ApiClient(stack.api, timeout=5.0)
    try:
        t_stop = t_rest = None
        c0 = c1 = None          # executed cycles (overruns skip deadlines; these count decisions)
        h0 = h1 = 0             # cycles with data missing while the host held a vCPU
        status: dict = {}
        deadline = t0 + timeout
        while time.monotonic() < deadline:
            status = watcher.call("status")
            now = time.monotonic()
            if c0 is None:
                c0 = status["stats"]["cycles"]
                h0 = status["network"].get("host_stalled_cycles", 0)
            if t_stop is None and status["state"] == "stopped":
                t_stop = now
                c1 = status["stats"]["cycles"]
                h1 = status["network"].get("host_stalled_cycles", 0)
                if not brakes:
                    t_rest = float("nan")
                    break
            if t_stop is not None and not any(j["enabled"] or abs(j["dq"]) > 1e-3 for j in status["joints"]):
                t_rest = now
                break
            time.sleep(0.005)
        if t_stop is None:
            raise AssertionError(f"{fault}: no protective stop within {timeout:.1f} s "
                                 f"(state {status.get('state')})")
        if t_rest is None:
            raise AssertionError(f"{fault}: stopped but drives still enabled or moving after {timeout:.1f} s")
    finally:
        watcher.close()
    reason = status.get("stop_reason") or ""
    result = SafeState(fault, reason, reason.split(":")[0], t_stop - t0,
                       t_rest - t0 if brakes else float("nan"), status, c1 - c0 + 1, h1 - h0)
    record_result(result)
    return result


def record_result(r: SafeState) -> None:
    path = os.environ.get(RESULTS_ENV)
    if not path:
        return
    with open(path, "a") as f:
        network = r.status.get("network") or {}
        f.write(json.dumps({"fault": r.fault, "reason": r.reason, "code": (r.status.get("stop") or {}).get("code"),
                            "to_stop": r.to_stop, "cycles": r.executed_cycles, "to_rest": r.to_rest,
                            # the controller's own starvation during the test (excused, never a stop)
                            "late_cycles": network.get("late_cycles", 0),
                            "host_stalled_cycles": r.host_stalled_cycles,
                            "starved_checks": network.get("starved_checks", 0)}) + "\n")


def assert_stays_still(stack: Stack, seconds: float = 0.4, settle: float = 0.3) -> None:
    """After a stop: the joints come to rest and stay there; no drive is enabled."""
    wait_for(lambda: not any(j["enabled"] or abs(j["dq"]) > 1e-3 for j in stack.status()["joints"]),
             3.0, "joints at rest after the stop")
    time.sleep(settle)
    first = np.array([j["q"] for j in stack.status()["joints"]])
    time.sleep(seconds)
    status = stack.status()
    q = np.array([j["q"] for j in status["joints"]])
    assert status["state"] == "stopped"
    assert not any(j["enabled"] for j in status["joints"]), status["joints"]
    assert np.all(np.abs(q - first) <= 3 * RESOLVER_STEP), (q - first)   # quantisation flicker only


def assert_motion_refused(stack: Stack) -> None:
    from spacearm.console.errors import CommandFailed
    for cmd, args in (("enable", {}), ("jog", {"joint": 1, "delta": 0.01})):
        try:
            stack.call(cmd, **args)
        except CommandFailed as exc:
            assert exc.code in ("protective_stop", "not_enabled", "drive_fault"), exc
        else:
            raise AssertionError(f"{cmd} accepted during a protective stop")


def recorded_stop_events(path: str) -> list[str]:
    """The protective-stop messages in a (possibly still open) recording."""
    from spacearm.controller.recording.mcap_reader import RecordingError, read_recording
    try:
        rec = read_recording(path)
    except RecordingError:
        return []            # nothing flushed yet (the recorder writes about once a second)
    return [m.data["message"] for m in rec.topic("/events") if m.data["kind"] == "protective_stop"]
