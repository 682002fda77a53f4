"""CANopen arm scenarios over a real bus transport (virtual in-process; loopback and
socketcan with the simulator as a separate `spacearm sim` process).

Faults are injected through the simulator's fault-injection unit (an SDO node at ID 126,
spacearm.drivers.sim_control.SimControl), so every scenario is the same code on every transport.
"""
from __future__ import annotations

import math
import os
import re
import signal
import time
from dataclasses import dataclass

import can
import pytest

from spacearm.base.canopen import od
from spacearm.base.config.bus import BusConfig, dump_toml, load_bus_config
from spacearm.base.canopen.cia402_defs import State
from spacearm.drivers.errors import BootError, DriverError, SdoError
from spacearm.drivers.devices import EeCommand, EeState
from spacearm.drivers.network import ArmCommand, ArmNetwork
from spacearm.drivers.sim_control import SimControl
from spacearm.firmware_sim.runner import Simulator

pytestmark = pytest.mark.hil


@pytest.fixture(autouse=True)
def master_at_daemon_priority():
    """The master under test runs in this process, at SCHED_FIFO 50 as the daemon runs it
    (`spacearm daemon --rt-priority 50`): its receive and timer threads, started from this
    thread, inherit the policy (and so does the in-process simulator on the virtual bus).
    At normal priority, CPU-bound neighbours starved them past the 3-period loss bound."""
    from spacearm.base.runtime.priority import use_fifo, use_normal

    use_fifo(50)
    yield
    use_normal()


@dataclass
class SimHandle:
    sim: Simulator | None      # in-process (virtual)
    proc: object | None        # subprocess (loopback, socketcan)


def scaled_config(time_scale: float) -> BusConfig:
    cfg = load_bus_config()
    b = cfg.bus
    bus = b.model_copy(update={"boot_timeout": b.boot_timeout * time_scale,
                               "sdo_timeout": min(10.0, b.sdo_timeout * time_scale),
                               "lockstep_timeout": min(10.0, b.lockstep_timeout * time_scale)})
    return BusConfig(bus=bus, nodes=cfg.nodes)


@pytest.fixture
def start_sim(bus_spec, launch, tmp_path):
    """start_sim(bus_config=None) -> SimHandle: in-process on virtual, else `spacearm sim`."""
    started = []

    def _start(config: BusConfig | None = None) -> SimHandle:
        config = config or load_bus_config()
        if bus_spec.startswith("virtual:"):
            sim = Simulator(bus_spec, config, control_node_id=od.SIM_CONTROL_NODE_DEFAULT).start()
            started.append(sim)
            return SimHandle(sim, None)
        path = tmp_path / f"bus{len(started)}.toml"
        path.write_text(dump_toml(config))
        started.append(None)
        proc = launch(["-m", "spacearm.console.main", "sim", "--stats", "--bus-config", path,
                       "--control-node", od.SIM_CONTROL_NODE_DEFAULT],
                      bus_spec=bus_spec, ready=r"nodes ready", timeout=30)
        return SimHandle(None, proc)

    yield _start
    for sim in started:
        if sim is not None:
            sim.stop()


@pytest.fixture
def simulator(start_sim):
    return start_sim()


@pytest.fixture
def arm(bus_spec, simulator, time_scale):
    net = ArmNetwork(bus_spec, scaled_config(time_scale))
    yield net
    net.close()


@pytest.fixture
def rig(arm):
    """The simulator's fault-injection unit, reached over the bus."""
    return SimControl(arm)


def test_boot_all_nodes_configured_and_operational(arm):
    arm.boot()
    state = arm.read()
    assert sorted(state.nodes) == sorted(n.name for n in arm.config.nodes)
    assert all(h.alive and h.nmt_state == od.NMT_STATE_OPERATIONAL for h in state.nodes.values())
    assert arm.sdo_read("joint_4", od.PRODUCER_HEARTBEAT) == 100          # configured by SDO
    assert arm.sdo_read("ft_sensor", od.COMM_CYCLE_PERIOD) == 20000
    state = arm.cycle()
    assert state.complete and len(state.joints) == 6 and state.ft is not None and state.end_effector is not None


def test_boot_with_a_node_missing_fails_naming_it(bus_spec, start_sim, time_scale):
    cfg = scaled_config(time_scale)
    start_sim(load_bus_config().without("joint_3"))          # joint 3 is not powered
    cfg = BusConfig(bus=cfg.bus.model_copy(update={"boot_timeout": 0.5 * time_scale}), nodes=cfg.nodes)
    net = ArmNetwork(bus_spec, cfg)
    try:
        with pytest.raises(BootError, match=r"no boot-up message .* from node 3 'joint_3' \(joint_drive\)$"):
            net.boot()
    finally:
        net.close()


@pytest.mark.vcan_vm   # the one scenario run inside the QEMU vcan VM (boot + CiA 402; ~1.5 min there)
def test_cia402_enable_csp_tracking_quick_stop_fault_and_reset(arm):
    arm.boot()
    state = arm.enable_all()
    assert state.all_enabled
    window = min(n.joint.following_error_window for n in arm.config.joints)
    q0 = state.joint_positions
    amplitude = [0.1, -0.08, 0.06, 0.12, -0.1, 0.15]
    n = 50
    worst = 0.0
    for k in range(1, n + 11):
        s = (1 - math.cos(math.pi * min(k, n) / n)) / 2
        targets = [q + a * s for q, a in zip(q0, amplitude)]
        state = arm.cycle(ArmCommand(joint_positions=targets))
        assert state.complete, f"cycle {k}: not every TPDO arrived"
        worst = max(worst, *(abs(j.following_error) for j in state.joints))
    assert worst < window
    for j, q, a in zip(state.joints, q0, amplitude):
        # state and error code: a drive that faulted mid-move (its consumer timed out on a starved
        # master's heartbeat, say) stops short, and the position alone would not say why
        assert j.position == pytest.approx(q + a, abs=3e-4), f"{j.name}: {j.state.name}, error {j.error_code:#06x}"
        assert j.enabled

    # quick stop of joint 1 while moving: QUICK STOP ACTIVE -> SWITCH ON DISABLED, brake on
    for k in range(1, 6):
        arm.cycle(ArmCommand(joint_positions=[q0[0] + 0.1 - 0.005 * k]))
    arm.quick_stop(0)
    state = arm.run_until(lambda s: s.joints[0].state == State.SWITCH_ON_DISABLED, 60)
    assert arm.cycle().joints[0].brake_engaged

    # fault: a following-error window of one increment makes joint 2 fault when it moves
    arm.poll_events()
    arm.sdo_write("joint_2", od.FOLLOWING_ERROR_WINDOW, 0, 1)
    arm.sdo_write("joint_2", od.FOLLOWING_ERROR_TIMEOUT, 0, 0)
    q = arm.read().joints[1].position
    state = _run_showing_joint(arm, lambda s: s.joints[1].fault, 30, ArmCommand(joint_positions=[None, q + 0.05]))
    events = arm.poll_events()
    assert any(e.kind == "emcy" and e.node == "joint_2" and e.code == od.EMCY_FOLLOWING_ERROR for e in events)
    state = _run_showing_joint(arm, lambda s: s.joints[1].state == State.FAULT, 100)
    assert state.joints[1].error_code == od.EMCY_FOLLOWING_ERROR
    arm.sdo_write("joint_2", od.FOLLOWING_ERROR_WINDOW, 0, round(window * arm.joints[1].k))
    arm.sdo_write("joint_2", od.FOLLOWING_ERROR_TIMEOUT, 0, 100)
    arm.fault_reset(1)
    arm.joints[0].axis.enable()
    state = arm.run_until(lambda s: s.all_enabled, 30)
    assert state.joints[1].error_code == 0
    assert "fault_cleared" in [e.kind for e in arm.poll_events()]


def _run_showing_joint(arm, predicate, max_cycles, command=None, joint=1):
    """arm.run_until, and when the condition is not reached, what the joint went through cycle by
    cycle (runs of equal readings) and the events: a failure on a slow machine says why."""
    seen = []

    def watch(s):
        j = s.joints[joint]
        seen.append((j.state.name, hex(j.error_code), j.fault, round(j.following_error, 4), s.complete,
                     s.nodes[f"joint_{joint + 1}"].alive))
        return predicate(s)
    try:
        return arm.run_until(watch, max_cycles, command)
    except DriverError as exc:
        runs = []
        for item in seen:
            if runs and item == runs[-1][0]:
                runs[-1][1] += 1
            else:
                runs.append([item, 1])
        raise AssertionError(f"{exc}; joint_{joint + 1} (state, error, fault, following error, complete, "
                             f"alive) x cycles: {runs}; events: "
                             f"{[(e.kind, e.node, hex(e.code or 0)) for e in arm.poll_events()]}") from exc


def _wait_events(arm, kind, names, timeout):
    got, deadline = {}, time.monotonic() + timeout
    while time.monotonic() < deadline and not set(names) <= set(got):
        for e in arm.poll_events():
            if e.kind == kind:
                got.setdefault(e.node, e)
        time.sleep(0.005)
    return got


def test_heartbeat_loss_of_any_node_detected_within_three_periods(arm, rig, time_scale):
    arm.boot()
    for cfg in arm.config.nodes:                             # every node, one at a time
        arm.poll_events()
        t0 = time.monotonic()
        rig.silence(cfg.name)
        got = _wait_events(arm, "heartbeat_lost", [cfg.name], 1.0 * time_scale)
        assert cfg.name in got, cfg.name
        assert got[cfg.name].time - t0 <= 3 * cfg.heartbeat_period * time_scale, cfg.name
        assert not arm.read().nodes[cfg.name].alive
        others = [n for n, h in arm.read().nodes.items() if n != cfg.name and not h.alive]
        assert not others, f"{others} reported lost while only {cfg.name} was silenced"
        rig.silence(cfg.name, False)
        assert cfg.name in _wait_events(arm, "heartbeat_restored", [cfg.name], 1.0 * time_scale)


@pytest.mark.multiprocess
def test_frozen_simulator_process_loses_every_node(arm, simulator, time_scale):
    arm.boot()
    nodes = arm.config.nodes
    arm.poll_events()
    os.killpg(simulator.proc.pid, signal.SIGSTOP)
    t0 = time.monotonic()
    try:
        got = _wait_events(arm, "heartbeat_lost", [n.name for n in nodes], 2.0 * time_scale)
    finally:
        os.killpg(simulator.proc.pid, signal.SIGCONT)
    assert set(got) == {n.name for n in nodes}
    for cfg in nodes:
        assert got[cfg.name].time - t0 <= 3 * cfg.heartbeat_period * time_scale, cfg.name
    back = _wait_events(arm, "heartbeat_restored", [n.name for n in nodes], 2.0 * time_scale)
    assert set(back) == {n.name for n in nodes}


def test_stalled_joint_following_error_fault_and_reset(arm, rig):
    arm.boot()
    arm.enable_all()
    arm.poll_events()
    rig.stall("joint_5")
    q = arm.read().joints[4].position
    state = arm.run_until(lambda s: s.joints[4].state == State.FAULT, 150,
                          ArmCommand(joint_positions=[None, None, None, None, q + 0.3]))
    assert state.joints[4].error_code == od.EMCY_FOLLOWING_ERROR
    assert all(j.enabled for i, j in enumerate(state.joints) if i != 4)
    emcy = [e for e in arm.poll_events() if e.kind == "emcy"]
    assert [(e.node, e.code) for e in emcy] == [("joint_5", od.EMCY_FOLLOWING_ERROR)]
    # a persisting over-temperature makes the reset fail, clearly
    rig.stall("joint_5", False)
    rig.set_temperature("joint_5", 95.0)
    arm.fault_reset("joint_5")
    for _ in range(12):
        arm.cycle()
    failed = [e for e in arm.poll_events() if e.kind == "fault_reset_failed"]
    assert failed and "joint_5" in failed[0].message and "over temperature" in failed[0].message
    rig.set_temperature("joint_5", 30.0)
    arm.fault_reset("joint_5")
    state = arm.run_until(lambda s: s.all_enabled, 30)
    assert state.joints[4].error_code == 0


def test_end_effector_and_ft_sensor(arm, rig):
    arm.boot()
    rig.set_wrench((12.0, 0.0, -3.0), (0.0, 0.5, 0.0))
    state = arm.cycle()
    assert state.ft.force == pytest.approx((12.0, 0.0, -3.0), abs=0.01)
    assert state.ft.torque == pytest.approx((0.0, 0.5, 0.0), abs=0.001)
    arm.tare_ft()
    state = arm.cycle()
    assert state.ft.tared and state.ft.force == pytest.approx((0, 0, 0), abs=0.01)
    arm.cycle(ArmCommand(end_effector=EeCommand.CLAMP))
    state = arm.run_until(lambda s: s.end_effector.state == EeState.LOCKED, 200)
    assert state.end_effector.grip == 1.0 and state.end_effector.screw_torque >= 8.0
    arm.cycle(ArmCommand(end_effector=EeCommand.RELEASE))
    state = arm.run_until(lambda s: s.end_effector.state == EeState.OPEN, 300)


def test_injected_frame_faults_are_counted(arm, rig):
    arm.boot()
    arm.enable_all()
    rig.corrupt_tpdos("joint_2", 2)
    rig.drop_tpdos("ft_sensor", 1)
    for _ in range(4):
        arm.cycle(timeout=0.1)
    assert arm.stats.malformed == 2 and arm.stats.tpdo_timeouts >= 1
    rig.abort_sdos("joint_6", 0x06060000)
    with pytest.raises(SdoError, match=r"node 6 'joint_6'.*0x06060000 \(Access failed due to a hardware error\)"):
        arm.sdo_read("joint_6", od.STATUSWORD)
    rig.abort_sdos("joint_6", None)
    assert arm.sdo_read("joint_6", od.DEVICE_TYPE) == 0x00020192
    assert arm.cycle().complete and arm.read().all_enabled


def test_sdo_aborts_are_clear_and_bad_frames_are_ignored(arm, bus_spec, simulator, open_test_bus):
    arm.boot()
    with pytest.raises(SdoError, match=r"node 3 'joint_3' \(joint_drive\): SDO read 0x5FFF:00 aborted with "
                                       r"0x06020000 \(Object does not exist\)"):
        arm.sdo_read("joint_3", 0x5FFF)
    with pytest.raises(SdoError, match=r"'ft_sensor'.*0x06010002 \(Attempt to write a read only object\)"):
        arm.sdo_write("ft_sensor", od.FT_STATUS, 0, 1)
    with pytest.raises(SdoError, match=r"0x06090011 \(Subindex does not exist\)"):
        arm.sdo_read("end_effector", od.IDENTITY, 5)
    with pytest.raises(SdoError, match=r"0x06070013"):
        arm.sdo_write("joint_1", od.TARGET_POSITION, 0, b"\x01")

    rogue = open_test_bus(bus_spec)
    garbage = [
        can.Message(arbitration_id=0x601, data=[0x40], is_extended_id=False),            # short SDO
        can.Message(arbitration_id=0x000, data=[0x01], is_extended_id=False),            # short NMT
        can.Message(arbitration_id=0x080, data=[1, 2, 3, 4], is_extended_id=False),     # long SYNC
        can.Message(arbitration_id=0x7E0, data=[1, 2, 3], is_extended_id=False),         # no service
        can.Message(arbitration_id=0x181, data=[1], is_extended_id=False),               # short TPDO
        can.Message(arbitration_id=0x701, data=[5, 5], is_extended_id=False),            # long heartbeat
        can.Message(arbitration_id=0x091, data=[1, 2], is_extended_id=False),            # short EMCY
        can.Message(arbitration_id=0x1ABCDE, data=[0] * 8, is_extended_id=True),
        can.Message(arbitration_id=0x602, data=[0xE0] + [0] * 7, is_extended_id=False),  # bad SDO command
        can.Message(arbitration_id=0x203, data=[0x0F], is_extended_id=False),            # short RPDO
    ]
    for _ in range(3):
        for msg in garbage:
            rogue.send(msg)
    state = arm.run_until(lambda s: s.complete, 5)
    time.sleep(0.1)
    assert arm.stats.malformed >= 12         # short TPDO/NMT, long heartbeat, short EMCY x3
    assert arm.stats.unknown >= 3 and arm.stats.ignored >= 3
    assert arm.stats.callback_errors == 0
    assert all(h.alive and h.nmt_state == od.NMT_STATE_OPERATIONAL for h in state.nodes.values())
    assert arm.sdo_read("joint_1", od.DEVICE_TYPE) == 0x00020192
    assert arm.enable_all().all_enabled
    if simulator.sim is not None:
        stats = simulator.sim.stats
        assert stats.malformed >= 6 and stats.internal_errors == 0
        assert simulator.sim.node(1).stats.malformed >= 3
    else:
        arm.close()
        os.killpg(simulator.proc.pid, signal.SIGTERM)
        simulator.proc.wait(10)
        out = simulator.proc.log_paths[0].read_text()
        m = re.search(r"malformed=(\d+).*internal_errors=(\d+)", out)
        assert m and int(m.group(1)) >= 6 and int(m.group(2)) == 0, out
