"""A stop over real Linux SocketCAN (issue 28: one stop path in the vcan VM): `spacearm sim`
as its own process on vcan0, the daemon's controller (lockstep, recording on) on the same
vcan0, joint 1 jogged at full speed and stopped by the operator's stop mid-jog, judged from
the daemon's recording by the bounds of controller/daemon/stop_metrics.py, and each drive's
state and brake read back over SDO. Runs where vcan0 exists: inside the test VM
(hil_tests/vm/runner.py), or on a host that has one; the host's separate-process stack
covers the other paths (hil_tests/test_stops_hil.py)."""
from __future__ import annotations

import time

import numpy as np
import pytest

from spacearm.base.canopen import od
from spacearm.base.canopen.cia402_defs import State, decode_statusword
from spacearm.base.config.bus import BusConfig, dump_toml, load_bus_config
from spacearm.controller.daemon.stop_metrics import recorded_stop, stop_figures
from tests.daemon.stop_run import ARM, PLANT, SteppedDaemon

pytestmark = [pytest.mark.hil, pytest.mark.multiprocess]


def _slow_machine_bus(path, time_scale: float):
    """The arm's bus with every timeout (and heartbeat period) times the VM's time scale:
    QEMU's software emulation runs the stack ~15x slower than the host."""
    cfg = load_bus_config()
    b = cfg.bus
    bus = b.model_copy(update={"boot_timeout": b.boot_timeout * time_scale,
                               "sdo_timeout": min(10.0, b.sdo_timeout * time_scale),
                               "lockstep_timeout": min(10.0, b.lockstep_timeout * time_scale),
                               "master_heartbeat_timeout": b.master_heartbeat_timeout * time_scale})
    nodes = [n.model_copy(update={"heartbeat_period": n.heartbeat_period * min(time_scale, 5.0)}) for n in cfg.nodes]
    path.write_text(dump_toml(BusConfig(bus=bus, nodes=nodes)))
    return path


@pytest.mark.vcan_vm
def test_operator_stop_mid_jog_over_socketcan(bus_spec, launch, tmp_path, time_scale):
    if not bus_spec.startswith("socketcan:"):
        pytest.skip("the SocketCAN stop path; on loopback the separate-process stack covers it")
    from spacearm.controller.daemon.daemon import Daemon, DaemonOptions
    started = time.monotonic()
    bus_config = _slow_machine_bus(tmp_path / "bus.toml", time_scale)
    launch(["-m", "spacearm.console.main", "sim", "--plant", str(PLANT), "--bus-config", bus_config],
           bus_spec=bus_spec, ready=r"nodes ready", timeout=30)
    daemon = Daemon(DaemonOptions(bus=bus_spec, arm=ARM, bus_config=bus_config, clock="lockstep", api=None,
                                  record_dir=tmp_path, period=0.02))
    try:
        daemon.start()
        run = SteppedDaemon(daemon, None)
        run.enable()
        run.jog_at_full_speed(0, delta=0.4)
        run.stop_and_settle(cycles=1.0)
        network = daemon.hardware.network
        drives = {f"joint_{i}": (decode_statusword(network.sdo_read(f"joint_{i}", od.STATUSWORD)),
                                 bool(network.sdo_read(f"joint_{i}", od.BRAKE_STATUS))) for i in range(1, 7)}
        rec = daemon.stop_recording()
    finally:
        daemon.shutdown()
    from spacearm.controller.recording.mcap_reader import read_recording
    recording = read_recording(rec["path"])
    cycles = [c.data for c in recording.topic("/cycle")]
    events = [e.data for e in recording.topic("/events")]
    t, q, t_stop = recorded_stop(cycles, events, 0.02)
    a_max = np.array([j.limits.acceleration for j in daemon.arm.joints])
    figures = stop_figures(t, q, t_stop, np.array(daemon.model.v_max), a_max, 0.02)
    f = figures[0]
    print(f"\nsocketcan operator stop, joint 1: v {f.v_stop:.4f} rad/s, peak/limit {f.peak / f.limit:.3f}, "
          f"distance {1e3 * f.distance:.1f} mrad (bound {1e3 * f.distance_bound:.1f}), time "
          f"{f.time_to_rest:.3f} s (bound {f.time_bound:.3f}); {time.monotonic() - started:.0f} s in all")
    assert next(e for e in events if e["kind"] == "protective_stop")["code"] == "operator_stop"
    assert f.v_stop > 0.98 * f.limit, f
    problems = [p for g in figures for p in g.problems()]
    assert not problems, problems
    wrong = {n: (s.value, brake) for n, (s, brake) in drives.items() if s is not State.SWITCH_ON_DISABLED or not brake}
    assert not wrong, f"drives read back over SDO: {wrong}; the stop table: switch on disabled, brakes on"
