"""The controller daemon: owns the CANopen master and runs the control cycle.

Each cycle: wait for the clock, read (SYNC, this SYNC's TPDOs), update (supervision and
the active mode, in ControllerCore), write (drive requests and RPDOs), record. The command
API runs on its own threads and only reads the published snapshot or queues commands.
"""
from __future__ import annotations

import sys
import threading
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable

import numpy as np

from spacearm.base.config.arm import ArmConfig, load_arm_config
from spacearm.controller.daemon.api_handlers import CommandHandlers
from spacearm.controller.daemon.clock import LockstepClock, RealTimeClock, Tick
from spacearm.controller.daemon.api_errors import ErrorCode
from spacearm.controller.daemon.command_api import ApiAddress, ApiError, CommandServer, Session
from spacearm.controller.daemon.core import ControllerCore, Event
from spacearm.controller.daemon.cycle_stats import CycleStats, CycleThresholds
from spacearm.controller.daemon.hardware import CanopenHardware, with_drive_limits
from spacearm.controller.daemon.idle_gate import IdleGate
from spacearm.controller.daemon.leases import ControlLease
from spacearm.controller.daemon.node_timing import NodeTiming
from spacearm.controller.daemon.overrun_cause import Overrun, OverrunMeter
from spacearm.controller.cycle import Mode
from spacearm.controller.daemon.recorder_process import RecorderProcess
from spacearm.controller.recording.can_trace import TraceLimit
from spacearm.controller.cycle import Command, Finding, FindingCode, MachineState, Measurement, built
from spacearm.controller.daemon.supervision import SupervisionLimits, Supervisor
from spacearm.base.kinematics import KinematicData, fk, matrix_to_rpy
from spacearm.base.kinematics.model import KinematicModel
from spacearm.controller.planning.motion_planner import MotionPlanner
from spacearm.base.config.bus import DEFAULT_BUS_CONFIG, check_axis_kinds, load_bus_config
from spacearm.base.runtime.priority import GIL_SWITCH_INTERVAL, describe, use_fifo


# s of controller time a SIGINT/SIGTERM waits for the arm to stop before powering off anyway
SHUTDOWN_STOP_LIMIT = 3.0
REALTIME_CYCLE_TIMEOUT = 2.0     # s a command waits for the cycle to take it: 100 cycles at 20 ms
LOCKSTEP_CYCLE_TIMEOUT = 30.0


@dataclass
class DaemonOptions:
    bus: str = "virtual:spacearm"
    arm: Path = Path("configs/arm/oru_testbed_6dof.toml")
    bus_config: Path = DEFAULT_BUS_CONFIG
    clock: str = "realtime"                      # "realtime" | "lockstep"
    period: float = 0.02                         # s
    api: str | None = "tcp:127.0.0.1:7440"       # None: no command API (in-process use)
    expose: bool = False
    token: str | None = None
    record_dir: Path | None = Path("runs")       # None: do not record
    camera: str | None = None                    # shared-memory frame ring of the camera (spacearm sim --camera)
    can_trace_limit: TraceLimit = field(default_factory=TraceLimit)   # raw CAN trace: size per file, files kept
    thresholds: CycleThresholds = field(default_factory=CycleThresholds)
    # The cycle shares the GIL with the CANopen receive thread, the API and the CAN trace's
    # batching thread (base/runtime/priority.py; the recording is serialised in its own
    # process, recorder_process.py); None leaves the interpreter's setting alone.
    gil_switch_interval: float | None = GIL_SWITCH_INTERVAL
    # SCHED_FIFO priority of the daemon's threads with the real-time clock (base/runtime/priority.py);
    # 0: normal scheduling. `spacearm daemon` asks for 50.
    rt_priority: int = 0


_STOPPED = MachineState.STOPPED    # tested every cycle: a module name, not the enum's member lookup


@dataclass(frozen=True)
class Snapshot:
    """What the API shows; replaced whole every cycle, never mutated."""
    tick: Tick
    measurement: Measurement
    command: Command
    state: str
    mode: str | None
    progress: float
    stop: Finding | None          # why the arm is in a protective stop
    motions_finished: int

    @property
    def stop_reason(self) -> str | None:
        return self.stop.message if self.stop is not None else None


class Daemon:
    def __init__(self, options: DaemonOptions):
        self.options = options
        self.arm: ArmConfig = load_arm_config(options.arm)
        self.model = KinematicModel.from_config(self.arm)
        self.planner = MotionPlanner(self.model, options.period, self.arm.cartesian)
        names = list(self.model.joint_names)
        self.supervisor = Supervisor(SupervisionLimits(
            np.array(self.model.q_min), np.array(self.model.q_max), np.array(self.model.v_max),
            following_error=np.array([j.drive.following_error for j in self.arm.joints]),
            settings=self.arm.supervision), names)
        self.core = ControllerCore(self.supervisor, names, options.period,
                                   a_max=np.array([j.limits.acceleration for j in self.arm.joints]))
        self.core.defer_answers = True     # answered after the cycle's snapshot: status shows the command
        self.lease = ControlLease()
        self.stats = CycleStats(options.thresholds)
        bus_config = load_bus_config(options.bus_config)
        check_axis_kinds(bus_config, [j.type for j in self.arm.joints], str(options.arm))
        bus_config = with_drive_limits(bus_config, self.model.q_min, self.model.q_max,
                                       [j.drive for j in self.arm.joints],
                                       [j.limits.acceleration for j in self.arm.joints])
        lockstep = options.clock == "lockstep"
        # Real time: wait for this SYNC's TPDOs at most 40 % of the period (8 ms at 20 ms),
        # leaving the rest to compute and write; a silent node costs a bounded share of the
        # cycle and shows up as missing data.
        self.hardware = CanopenHardware(options.bus, bus_config, lockstep=lockstep,
                                        realtime_budget=0.4 * options.period)
        if self.hardware.dof != self.model.nq:
            raise ValueError(f"bus config {options.bus_config} has {self.hardware.dof} joint drives, "
                             f"arm {options.arm} has {self.model.nq} joints")
        # what each real-time overrun spent its time on (a lockstep cycle has no deadline)
        self.overruns = OverrunMeter() if not lockstep else None
        self.overrun_log: list[Overrun] = []         # the last judged overruns
        self.clock = LockstepClock(options.period) if lockstep else \
            RealTimeClock(options.period, on_overrun=self.overruns.overrun_found)
        # the nodes' answers in time (a starved simulator or hub shows here before it stops the arm);
        # lockstep waits as long as the nodes take, so only the heartbeats say anything there
        self.node_timing = NodeTiming(self.hardware.realtime_budget if not lockstep else 0.0, lockstep=lockstep)
        self._reported_level = "ok"
        # each node's health record and heartbeat period, as _watch_nodes reads them every cycle
        network = self.hardware.network
        self._heartbeat_sources = [(name, h, network.drivers[name].cfg.heartbeat_period)
                                   for name, h in network.health.items()]
        # Reactive modes other features provide, by name ("approach", "impedance", "oru", ...).
        # A factory builds a Mode from validated arguments; composite modes (the ORU task
        # flow) build their sub-modes through the same registry.
        self.mode_factories: dict[str, Callable[..., Mode]] = {}
        self.vision = None                           # VisionWorker once a camera is attached
        self.recorder: RecorderProcess | None = None
        self.snapshot: Snapshot | None = None
        self.event_log: list[dict[str, Any]] = []    # last events, for status
        self.scheduling = "normal"   # the cycle's policy, or why the one asked for was refused
        self._stop = threading.Event()
        self._last_stats_time = -1.0
        # A lockstep cycle's wall time is the machine's speed, not a fault: there the timeout only
        # tells a console that the cycle is not running at all.
        # the API's status waits for the cycle's idle time (idle_gate.py); in-process callers do not
        self.idle_gate = IdleGate()
        self.handlers = CommandHandlers(self.core, self.lease, self.planner, self._status_when_idle,
                                        RecordingControl(self), self.model.nq,
                                        cycle_timeout=LOCKSTEP_CYCLE_TIMEOUT if lockstep else REALTIME_CYCLE_TIMEOUT)
        # Named postures for `move joints NAME`: the arm file's [postures], and "home" from the
        # joints' home angles unless the file names its own.
        self.handlers.postures = {"home": [j.home for j in self.arm.joints], **self.arm.postures}
        self.handlers.mode_factories = self.mode_factories   # the same dict: "approach" once a camera is attached
        from spacearm.controller.daemon.oru_commands import install_oru   # here: it imports the daemon's handler types
        self.oru = install_oru(self)                      # "impedance", "oru" modes and oru.* commands
        self.server: CommandServer | None = None
        if options.api:
            self.server = CommandServer(ApiAddress.parse(options.api), self.handlers.handle,
                                        self._session_closed, options.expose, options.token)

    # ---- life cycle --------------------------------------------------------------------
    def start(self) -> None:
        """Boot the CAN network (all nodes configured and operational), start recording and
        the command API. The arm comes up disabled with brakes on."""
        if self.options.gil_switch_interval is not None:
            sys.setswitchinterval(self.options.gil_switch_interval)
        problem = None
        if self.options.clock == "realtime" and self.options.rt_priority:
            # Before any thread starts, so the receive, API and CAN trace threads inherit it and
            # never hold the GIL at a lower priority than the waiting cycle.
            problem = use_fifo(self.options.rt_priority)
        self.scheduling = problem or describe()
        if self.options.clock != "realtime" and self.options.rt_priority:
            # Lockstep: the cycle runs flat out at normal priority (at FIFO it would take a core
            # from everything else), but the drives time the master's heartbeat in wall time, so
            # a cycle starved by other load must not silence it: the timer thread alone is FIFO.
            self.hardware.network.timer_priority = self.options.rt_priority
        if self.server is not None:
            # Listening from before bring-up: a stop sent while the drives boot is taken and
            # applied at the first cycle; other commands are refused until then (api_handlers.py).
            self.server.start()
        try:
            self.hardware.start()
        except BaseException:
            if self.server is not None:
                self.server.stop()
            raise
        if self.hardware.network.timer_priority:
            self.scheduling += f" (heartbeat timer: {self.hardware.network.timer_scheduling})"
        if self.options.camera:
            from spacearm.base.vision.frames import ShmFrameRing
            self.attach_vision(ShmFrameRing.attach(self.options.camera))
        if self.options.record_dir is not None:
            self.start_recording(None)
        self.cycle_once()

    def attach_vision(self, source) -> None:
        """Run the vision pipeline on `source` (a FrameSource) and register
        mode_factories["approach"] (controller/daemon/approach_mode.py). Real time: on its own
        thread on a free-running camera; lockstep: in the cycle, on a camera triggered in plant
        time (controller/vision/lockstep.py), so a lockstep run's results do not depend on load."""
        from spacearm.base.config.scene import load_scene
        from spacearm.controller.daemon.approach_mode import approach_factory
        from spacearm.base.vision.config import load_mount
        from spacearm.controller.vision.lockstep import LockstepVision
        from spacearm.controller.vision.worker import VisionWorker
        if isinstance(self.clock, LockstepClock):
            self.vision = LockstepVision(source).start()
        else:
            self.vision = VisionWorker(source, cycle_priority=self.options.rt_priority).start()
        self.mode_factories["approach"] = approach_factory(
            self.model, load_scene(), self.vision, load_mount().end_T_camera.matrix(),
            self.vision.pipeline.marker.marker_T_oru, self.arm.cartesian, self.options.period, self.arm.approach)

    def run(self, max_cycles: int | None = None) -> None:
        cycles = 0
        while not self._stop.is_set() and (max_cycles is None or cycles < max_cycles):
            self.cycle_once()
            cycles += 1
        if self._stop.is_set():
            self.stop_before_exit()

    def stop_before_exit(self, limit: float = SHUTDOWN_STOP_LIMIT) -> None:
        """SIGINT/SIGTERM: a moving or enabled arm is stopped as any protective stop is
        (controller/daemon/stops.py, `shutdown`), cycling on until it is at rest with the
        drives off, at most `limit` s of controller time; shutdown then powers off."""
        core = self.core
        if core.state in (MachineState.ENABLED, MachineState.ENABLING) and core.last_measurement is not None:
            core.protective_stop(core.last_measurement.time, Finding(
                FindingCode.SHUTDOWN, "daemon shutting down (SIGINT/SIGTERM): stopping the arm first"))
        cycles = 0
        while not core.stop_finished and cycles * self.options.period < limit:
            self.cycle_once()
            cycles += 1

    def request_stop(self) -> None:
        self._stop.set()

    def shutdown(self) -> None:
        """Disable the drives (brakes on), stop the network, close the recording and API."""
        if self.server is not None:
            self.server.stop()
        if self.vision is not None:
            self.vision.stop()
        try:
            self.hardware.stop()
        finally:
            if self.recorder is not None:
                self.recorder.close()
                self.recorder = None

    # ---- the cycle ---------------------------------------------------------------------
    def cycle_once(self) -> Snapshot:
        tick = self.clock.next_tick()
        self.idle_gate.cycle_started()
        measurement = self.hardware.read(tick.time)
        if self.vision is not None:
            self.vision.on_cycle(measurement.sync_counter)
        try:
            return self._cycle(tick, measurement)
        finally:
            self.core.answer_commands()     # a cycle that raised still answers what it took
            if self.overruns is not None:
                self._judge_overruns(tick)
            self.idle_gate.cycle_ended(getattr(self.clock, "next_deadline", None))

    def _judge_overruns(self, tick: Tick) -> None:
        self.overruns.end(tick.cycle, tick.deadline, tick.deadline + self.clock.period, self.hardware.last_io_wait)
        for overrun in self.overruns.pop_judged():
            self.stats.overrun_causes[overrun.cause] += 1
            self.core._event(tick.time, "overrun", overrun.describe())
            self.overrun_log = (self.overrun_log + [overrun])[-20:]

    def _cycle(self, tick, measurement: Measurement) -> Snapshot:
        command = self.core.update(measurement)
        self.hardware.write(command, self.core.drive_request if self.core.state is _STOPPED else None)
        events = self.core.drain_events()
        if events and any(e.kind == "reset" for e in events):     # most cycles: none, no generator
            self.hardware.fault_reset()
        execution = time.monotonic() - tick.woke_at
        self.stats.add(tick.period_error, execution, tick.skipped, self.hardware.last_io_wait)
        self._watch_nodes(measurement, tick.skipped > 0)
        core = self.core
        mode = core.mode
        # every cycle: the fields in Snapshot's order without the frozen dataclass's __init__
        snapshot = built(Snapshot, {"tick": tick, "measurement": measurement, "command": command,
                                    "state": core.state, "mode": mode.name if mode is not None else None,
                                    "progress": core.mode_progress(), "stop": core.stop_reason,
                                    "motions_finished": core.motions_finished})
        self.snapshot = snapshot
        self.core.answer_commands()
        self._record(snapshot, execution, events)
        return snapshot

    def _watch_nodes(self, m: Measurement, starved: bool) -> None:
        # the snapshot is still the last cycle's: the nodes missing at its read
        last_missing = self.snapshot.measurement.missing if self.snapshot is not None else ()
        # lockstep: heartbeat gaps follow the machine's speed, and the timing leaves them out
        heartbeats = {} if self.node_timing.lockstep else {
            name: (h.last_heartbeat, period) for name, h, period in self._heartbeat_sources}
        self.node_timing.add(self.hardware.last_io_wait, not m.missing, heartbeats,
                             host_stalled=m.host_stalled,
                             last_answered_late=bool(m.answered_late)
                             and set(m.answered_late) >= set(last_missing), starved=starved,
                             bridged=m.bridged)
        if self.stats.cycles % 50 == 0:         # once a second: say it when the level changes
            summary = self.node_timing_summary()
            if summary.level != self._reported_level:
                self._reported_level = summary.level
                self.core._event(m.time, "nodes", summary.message)

    def _record(self, s: Snapshot, execution: float, events: list[Event]) -> None:
        for event in events:
            self.event_log = (self.event_log + [event.as_dict()])[-20:]
        recorder = self.recorder  # one file per cycle even if record start/stop swaps it now
        if recorder is None:
            return
        m = s.measurement
        recorder.put_cycle(s.tick.time, m.sync_counter, s.tick.cycle, s.command.q, self._velocity_offsets_sent(),
                           m.q, m.dq, m.tau, m.wrench, m.end_effector, s.state, s.mode or "",
                           s.tick.period_error, execution, self.hardware.last_io_wait, m.missing)
        for event in events:
            recorder.put("/events", event.time, event.as_dict())
        if s.tick.time - self._last_stats_time >= 1.0:
            self._last_stats_time = s.tick.time
            recorder.put("/stats", s.tick.time, self.stats.summary().as_dict())

    def _velocity_offsets_sent(self) -> list[float]:
        """The velocity offset (60B1h, rad/s) each drive was sent with this cycle's target: the
        command's planned velocity, or the last one sent when a command carries none (the
        drivers keep it). The diagnosis replays it as sent instead of rebuilding it."""
        return [joint.velocity_ff for joint in self.hardware.network.joints]

    # ---- recording ---------------------------------------------------------------------
    def start_recording(self, path: str | None) -> dict:
        """Start a new recording file; the previous one (if any) is closed complete.

        Called from API threads: the new recorder replaces the old in one assignment, so each
        cycle goes wholly to one file or the other."""
        if path is None:
            stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%SZ")
            path = str(Path(self.options.record_dir or "runs") / f"{stamp}.mcap")
        new = RecorderProcess(Path(path), {
            "arm": str(self.options.arm), "bus": self.options.bus, "clock": self.options.clock,
            "period": repr(self.options.period), "joints": ",".join(self.model.joint_names)},
            bus_spec=self.options.bus, time_origin_ns=self._time_origin_ns(),
            can_trace_limit=self.options.can_trace_limit, lossless=self.options.clock == "lockstep")
        old, self.recorder = self.recorder, new
        if old is not None:
            old.close(grace=2 * self.options.period)
        return {"path": str(new.path), "can_log": str(new.can_log)}

    def _time_origin_ns(self) -> int:
        """UTC wall clock of controller time 0, as of now: the recording's log times are real dates
        (with the lockstep clock controller time runs faster than the wall clock; the origin
        is where the recording started)."""
        now = self.snapshot.tick.time if self.snapshot is not None else 0.0
        return time.time_ns() - int(round(now * 1e9))

    def stop_recording(self) -> dict:
        old, self.recorder = self.recorder, None
        if old is None:
            raise ValueError("not recording")
        return vars(old.close(grace=2 * self.options.period))

    # ---- status --------------------------------------------------------------------------
    def status(self) -> dict[str, Any]:
        s = self.snapshot
        if s is None:
            return {"state": "starting"}
        m = s.measurement
        return {
            "state": s.state, "mode": s.mode, "progress": s.progress, "stop_reason": s.stop_reason,
            "stop": s.stop.as_dict() if s.stop is not None else None,   # code, message, node, joint
            "motions_finished": s.motions_finished,
            "time": s.tick.time, "cycle": s.tick.cycle, "sync_counter": m.sync_counter,
            "woke_at": s.tick.woke_at,   # monotonic s (machine-wide): state latency, web console timing
            "clock": self.options.clock, "period": self.options.period, "bus": self.options.bus,
            "scheduling": self.scheduling,
            "arm": self.model.name,
            "joints": [{"name": name, "q": float(m.q[i]), "q_cmd": float(s.command.q[i]),
                        "dq": float(m.dq[i]), "tau": float(m.tau[i]),
                        "enabled": bool(m.joints_enabled[i]), "fault": bool(m.joints_faulted[i]),
                        "q_min": float(self.model.q_min[i]), "q_max": float(self.model.q_max[i])}
                       for i, name in enumerate(self.model.joint_names)],
            "tool": tool_pose(self.model, m.q),   # measured, base frame: xyz m, rpy rad (R = Rz Ry Rx)
            "wrench": m.wrench.tolist(), "end_effector": m.end_effector,
            "stats": self.stats.summary().as_dict(),
            "control": {"held": self.lease.held, "holder": self.lease.holder},
            "recording": vars(recorder.info()) if (recorder := self.recorder) else None,
            "events": list(self.event_log),
            "network": self.hardware.statistics(),
            # per node: SDO writes at bring-up, optional objects its EDS lacks, how it is guarded
            "bringup": self.hardware.bringup_report(),
            "nodes": self.node_timing_summary().as_dict(),   # are the simulator/hub/bus answering in time
        }

    def _status_when_idle(self) -> dict:
        self.idle_gate.wait_for_idle()
        return self.status()

    def node_timing_summary(self):
        """The daemon's view of the nodes' timing, with the simulator's and hub's own reports
        (real-time clock only: in lockstep nobody waits for anybody's timer)."""
        lockstep = self.options.clock == "lockstep"
        return self.node_timing.summary(None if lockstep else self.hardware.peers.reports(), time.monotonic())

    def _session_closed(self, session: Session) -> None:
        pass  # the control lease is keyed, not tied to a connection (see leases.py)


def tool_pose(model: KinematicModel, q: np.ndarray) -> dict[str, list[float]]:
    """The tool's pose for joint positions q (its own KinematicData: API threads call this)."""
    T = fk(model, KinematicData(model), np.asarray(q, float))
    return {"xyz": T[:3, 3].tolist(), "rpy": matrix_to_rpy(T[:3, :3]).tolist()}


class RecordingControl:
    def __init__(self, daemon: Daemon):
        self.daemon = daemon

    def start(self, path: str | None) -> dict:
        # A directory the operator named must exist: a typo must not silently become new folders
        # (the default, runs/, is created as before).
        if path is not None and not Path(path).parent.is_dir():
            raise ApiError(f"no directory {str(Path(path).parent)!r} for the recording (create it first)",
                           ErrorCode.BAD_ARGUMENT)
        return self.daemon.start_recording(path)

    def stop(self) -> dict:
        try:
            return self.daemon.stop_recording()
        except ValueError as exc:
            raise ApiError(str(exc), ErrorCode.RECORDING) from None
