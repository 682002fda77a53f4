"""`record-sim`: run a commanded trajectory through controller and simulator in lockstep.

The CAN path: simulated nodes and the daemon (lockstep clock) in this process on a private
virtual bus; the daemon enables the arm, records, and plays the trajectory as a planned
mode. The direct path (``direct_sim``) is the fast equivalent for the benchmark.

A trajectory sends no velocity feed-forward (``Trajectory.sample``); with ``velocity_offset``
the CAN path sends its velocity as the drives' velocity offset (60B1h), as the daemon's own
moves do, so the replay of such recordings (``command_timing.py``) can be checked against it.
"""
from __future__ import annotations

import tempfile
import threading
import time
import uuid
from pathlib import Path

import numpy as np

from spacearm.controller.daemon.daemon import Daemon, DaemonOptions
from spacearm.controller.modes import PlannedMode
from spacearm.controller.planning.joint_move import JointSetpoint
from spacearm.offline.diagnosis.direct_sim import simulate
from spacearm.offline.diagnosis.recording_io import RecordingTable, write_csv
from spacearm.offline.diagnosis.trajectory import Trajectory
from spacearm.controller.recording.csv_export import export_csv
from spacearm.base.config.bus import DEFAULT_BUS_CONFIG, load_bus_config
from spacearm.firmware_sim.plant import PlantConfig
from spacearm.firmware_sim.runner import start_simulator

DEFAULT_ARM = Path("configs/arm/oru_testbed_6dof.toml")


class RecordSimError(RuntimeError):
    pass


def starting_at(config: PlantConfig, q0: np.ndarray) -> PlantConfig:
    """The plant with its joints resting at the trajectory's first point (the run starts there)."""
    joints = [config.joint_params(i) for i in range(len(q0))]
    return config.model_copy(update={"joints": [p.model_copy(update={"initial_position": float(q)})
                                                for p, q in zip(joints, q0)]})


class WithVelocityOffset:
    """A trajectory as a plan whose setpoints carry its velocity (the daemon's moves' way)."""

    def __init__(self, trajectory: Trajectory):
        self.trajectory = trajectory
        self.duration = trajectory.duration
        self._velocity = np.gradient(trajectory.q, trajectory.t, axis=0)

    def sample(self, t: float) -> JointSetpoint:
        q = self.trajectory.sample(t).q
        dq = np.array([np.interp(t, self.trajectory.t, v) for v in self._velocity.T])
        return JointSetpoint(q, dq, np.zeros_like(q))


def record_can(config: PlantConfig, trajectory: Trajectory, out: Path, arm: Path = DEFAULT_ARM,
               bus_config: Path = DEFAULT_BUS_CONFIG, timeout: float = 3600.0, clock: str = "lockstep",
               velocity_offset: bool = False) -> Path:
    """Record over CAN; writes MCAP (out.mcap) or the wide CSV (out.csv). Returns out.
    `velocity_offset`: the setpoints carry the trajectory's velocity (see the module's note)."""
    out = Path(out)
    bus = f"virtual:record-sim-{uuid.uuid4().hex[:8]}"
    workdir = tempfile.TemporaryDirectory()
    bus_config = _patient_heartbeats(Path(bus_config), Path(workdir.name))
    simulator = start_simulator(bus, bus_config, starting_at(config, trajectory.q[0]),
                                time_base="sync" if clock == "lockstep" else "wall")
    daemon = Daemon(DaemonOptions(bus=bus, arm=arm, bus_config=bus_config, clock=clock, api=None,
                                  record_dir=None))
    thread = None
    mcap = out if out.suffix == ".mcap" else Path(workdir.name) / "run.mcap"
    try:
        daemon.start()
        thread = threading.Thread(target=daemon.run, name="record-sim-cycle", daemon=True)
        thread.start()
        core = daemon.core
        core.submit(core.cmd_enable)
        _wait(daemon, lambda s: s.state == "enabled", 10.0, "drives did not enable")
        daemon.start_recording(str(mcap))
        plan = WithVelocityOffset(trajectory) if velocity_offset else trajectory
        mode = PlannedMode("trajectory", plan, 0.0, f"{len(trajectory.t)} points, {trajectory.duration:.1f} s")
        answer = core.submit(lambda t, m: core.start_planned(t, m, mode, None))
        _wait(daemon, lambda s: s.motions_finished >= answer["motion"] or s.state == "stopped", timeout,
              "trajectory did not finish")
        if daemon.snapshot.state == "stopped":
            raise RecordSimError(f"protective stop during the trajectory: {daemon.snapshot.stop_reason}")
        daemon.stop_recording()
    finally:
        daemon.request_stop()
        if thread is not None:
            thread.join(timeout=5)
        daemon.shutdown()
        simulator.stop()
    if out.suffix != ".mcap":
        export_csv(mcap, out)
    workdir.cleanup()
    return out


def record_direct(config: PlantConfig, trajectory: Trajectory, out: Path | None, dt: float = 0.02,
                  hold_cycles: int = 2) -> RecordingTable:
    """The direct path: same plant and servo law, no bus. Writes the wide CSV when out is given."""
    q_cmd = trajectory.resampled(dt)
    q_cmd = np.vstack([np.repeat(q_cmd[:1], hold_cycles, axis=0), q_cmd])
    traces = simulate(starting_at(config, q_cmd[0]), q_cmd, dt)
    table = RecordingTable(traces.t, traces.q_cmd, traces.q, traces.dq, traces.tau, traces.wrench)
    if out is not None:
        write_csv(out, table)
    return table


def _patient_heartbeats(path: Path, workdir: Path, period: float = 0.5) -> Path:
    """The bus config with heartbeats of at least `period` s. A lockstep run in one process
    on a loaded machine can starve the heartbeat threads for a few hundred ms; heartbeats
    only supervise (they never enter the recorded physics), so a slower heartbeat keeps the
    recording from ending in a spurious protective stop."""
    import tomli_w
    config = load_bus_config(path)
    nodes = [n.model_copy(update={"heartbeat_period": max(n.heartbeat_period, period)}) for n in config.nodes]
    bus = config.bus.model_copy(update={
        "master_heartbeat_period": max(config.bus.master_heartbeat_period, period),
        "master_heartbeat_timeout": max(config.bus.master_heartbeat_timeout, 3 * period)})
    data = config.model_copy(update={"nodes": nodes, "bus": bus}).model_dump(mode="json", exclude_none=True)
    out = workdir / "bus.toml"
    out.write_text(tomli_w.dumps(data))
    return out


def _wait(daemon: Daemon, done, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        s = daemon.snapshot
        if s is not None and done(s):
            return
        time.sleep(0.002)
    raise RecordSimError(f"{what} within {timeout:.0f} s")
