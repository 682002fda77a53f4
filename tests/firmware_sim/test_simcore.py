"""The simulator's compiled core (firmware_sim/_simcore.c) computes what the pure-Python path
computes, bit for bit: a joint's SYNC period on random plants and servo laws, the drive's
actual values, and whole lockstep runs (recording, plant state after every cycle, every CAN
frame of the cycle thread). Skipped, with the reason, where the core was not built."""
from __future__ import annotations

import math
import random

import pytest
from hypothesis import given, settings, strategies as st

from spacearm.firmware_sim import simcore
from spacearm.firmware_sim.joint_drive import SERVO_CSP, SERVO_OFF
from spacearm.firmware_sim.plant import JointModel, JointParams
from tests.firmware_sim.core_switch import core_switched, needs_core


class _Law:
    """A drive's servo law for a period as joint_drive.JointDriveNode gives it, and its _servo()."""

    def __init__(self, kind, q_start, q_end, v_ff, torque_ff, joint):
        self.kind, self.q_start, self.q_end, self.v_ff, self.torque_ff = kind, q_start, q_end, v_ff, torque_ff
        self.joint, self.q_ref, self.v_ref = joint, None, None

    def servo(self, s, q_meas, qd):
        if self.kind == SERVO_OFF:
            self.q_ref, self.v_ref = q_meas, 0.0
            return 0.0
        from spacearm.firmware_sim.joint_drive import servo_torque
        self.q_ref = self.q_start + s * (self.q_end - self.q_start)
        self.v_ref = self.v_ff
        return servo_torque(self.joint, self.q_ref, self.v_ref, q_meas, qd) + self.torque_ff

    def law(self):
        return self.kind, self.q_start, self.q_end, self.v_ff, self.torque_ff, self.finish

    def finish(self, q_ref, v_ref):
        self.q_ref, self.v_ref = q_ref, v_ref


def _joint(params, q, qd, motor_torque, brake, load_amplitude, max_torque):
    joint = JointModel(params=params, q=q, load_amplitude=load_amplitude)
    joint.qd, joint.thetad, joint.motor_torque, joint.brake_engaged = qd, qd, motor_torque, brake
    joint.max_motor_torque = max_torque
    return joint


def _state(joint, law):
    return repr((joint.q, joint.qd, joint.theta, joint.thetad, joint.motor_torque, law.q_ref, law.v_ref))


finite = st.floats(-3.0, 3.0, allow_nan=False)


def random_fields(rng: random.Random, prismatic: bool, friction: bool, te: bool) -> dict:
    """A random joint's parameters (rigid gear) for JointParams, with the effects asked for."""
    fields = dict(servo_bandwidth_hz=rng.uniform(1.0, 50.0), servo_damping=rng.uniform(0.3, 2.0),
                  gear_ratio=rng.uniform(1.0, 200.0), gear_efficiency=rng.uniform(0.5, 1.0),
                  link_inertia=rng.uniform(0.0, 20.0), torque_limit=rng.choice([0.0, rng.uniform(0.01, 5.0)]),
                  encoder_bias=rng.uniform(-1e-3, 1e-3), gravity_angle=rng.uniform(-3.0, 3.0))
    if prismatic:
        fields.update(kind="prismatic", encoder_quantum=rng.choice([0.0, 1e-6]))
    else:
        fields.update(resolver_arcsec=rng.choice([0.0, 25.0]))
    if friction:
        fields.update(coulomb_friction=rng.uniform(0.0, 5.0), viscous_friction=rng.uniform(0.0, 5.0),
                      stribeck_friction=rng.uniform(0.0, 3.0), stribeck_velocity=rng.uniform(0.001, 0.1))
    if te:
        fields.update(te_amplitude=rng.uniform(1e-5, 1e-3), te_harmonic=rng.uniform(1.0, 3.0),
                      te_phase=rng.uniform(-3.0, 3.0))
    return fields


@needs_core
@settings(max_examples=300, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), q=finite, qd=finite, q_end=finite, torque_ff=st.floats(-2.0, 2.0),
       kind=st.sampled_from([SERVO_OFF, SERVO_CSP]), brake=st.booleans(), friction=st.booleans(),
       te=st.booleans(), prismatic=st.booleans(), substeps=st.integers(1, 20))
def test_a_period_in_the_core_is_the_python_period(seed, q, qd, q_end, torque_ff, kind, brake, friction, te,
                                                     prismatic, substeps):
    rng = random.Random(seed)
    params = JointParams(**random_fields(rng, prismatic, friction, te))
    amplitude = rng.choice([0.0, rng.uniform(-50.0, 50.0)])
    max_torque = rng.choice([math.inf, rng.uniform(0.1, 10.0)])
    n = substeps
    fractions = [(k + 1) / n for k in range(n)]
    h = 0.02 / n
    external = rng.uniform(-1.0, 1.0)
    results = []
    for _ in range(2):
        joint = _joint(params, q, qd, 0.3, brake, amplitude, max_torque)
        joint.external_torque = external
        law = _Law(kind, q, q_end, (q_end - q) / 0.02, torque_ff, joint)
        joint.controller = law.servo
        joint.period_servo = (law.servo, law.law)
        results.append((joint, law))
    core_joint, core_law = results[0]
    assert core_joint._core_period(fractions, h, core_law.law(), core_joint._core_constants())
    py_joint, py_law = results[1]
    py_joint.period_servo = None
    py_joint.substeps(fractions, h)
    assert _state(core_joint, core_law) == _state(py_joint, py_law)


@needs_core
def test_a_period_python_raises_on_is_left_to_python():
    """round() of a NaN position raises in Python: the core changes nothing and says so."""
    joint = _joint(JointParams(), math.nan, 0.0, 0.0, False, 0.0, math.inf)
    law = _Law(SERVO_CSP, 0.0, 0.1, 5.0, 0.0, joint)
    joint.controller, joint.period_servo = law.servo, (law.servo, law.law)
    assert not joint._core_period([0.5, 1.0], 0.01, law.law(), joint._core_constants())
    assert math.isnan(joint.q) and joint.motor_torque == 0.0 and law.q_ref is None
    with pytest.raises(ValueError):
        joint.substeps([0.5, 1.0], 0.01)


@needs_core
@settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), min_size=8, max_size=8))
def test_actual_values_are_the_python_counts(values):
    k, rated, q_rep, q_ref, qd_rep, torque, q_meas, temperature = values

    def i32(x):
        return max(-2**31, min(2**31 - 1, round(x)))
    try:
        expected = (i32(q_rep * k), i32(q_ref * k), i32(qd_rep * k),
                    max(-32768, min(32767, round(torque / rated * 1000.0))), i32((q_ref - q_meas) * k),
                    max(-32768, min(32767, round(temperature * 10.0))))
    except (ValueError, OverflowError, ZeroDivisionError):
        expected = None
    if rated == 0.0:
        return           # Python divides by zero and raises; the drive's rated torque is never 0 (EDS)
    assert simcore.core.actual_values(*values) == expected


def _run(name, tmp_path, monkeypatch, use_core):
    from bench.lockstep_fingerprint import run_scenario
    monkeypatch.setattr(simcore, "core", simcore.core if use_core else None)
    folder = tmp_path / ("core" if use_core else "pure")
    folder.mkdir()
    return run_scenario(name, folder)


@needs_core
@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["effects", "cell"])
def test_a_lockstep_run_with_the_core_is_the_pure_run(scenario, tmp_path, monkeypatch):
    """A scripted lockstep run (bench/lockstep_fingerprint.py: every joint effect on, or the
    contact cell with a drive fault and its stops): the recording's /cycle records, the plant
    state after every cycle and every CAN frame of the cycle thread agree bit for bit."""
    core = _run(scenario, tmp_path, monkeypatch, True)
    pure = _run(scenario, tmp_path, monkeypatch, False)
    assert len(core["cycles"]) == len(pure["cycles"]) > 100
    assert repr(core["cycles"]) == repr(pure["cycles"])
    assert repr([c[1] for c in core["per_cycle"]]) == repr([c[1] for c in pure["per_cycle"]])
    assert core["frames"] == pure["frames"]


DRIVE_FIELDS = ("state", "prev_cw", "mode", "q_ref", "q_start", "q_end", "v_ref", "v_ff", "limit_active", "torque_ff",
                "prev_cw_setpoint", "halt", "ramp_dec", "ramp_quick", "_ramp_from_actual", "pp_target",
                "target_reached", "fe_time", "error_code")


_DRIVES: list = []


def _drive():
    """A joint drive just powered on (one built per test session: loading the EDS is slow)."""
    if not _DRIVES:
        from spacearm.base.config.bus import EDS_DIR
        from spacearm.firmware_sim.joint_drive import JointDriveNode
        from spacearm.firmware_sim.plant import Plant
        _DRIVES.append(JointDriveNode(3, EDS_DIR / "joint_drive.eds", "joint_1", Plant.create(1), 0))
    drive = _DRIVES[0]
    joint = drive.joint           # the plant's joint outlives the example that moved it: at rest at 0
    joint.q = joint.theta = joint.qd = joint.thetad = joint.motor_torque = joint.torque_reported = 0.0
    joint.temperature = 25.0
    drive.power_on()
    return drive


@needs_core
@settings(max_examples=400, deadline=None)
@given(state=st.sampled_from(["SWITCH_ON_DISABLED", "READY_TO_SWITCH_ON", "SWITCHED_ON", "OPERATION_ENABLED",
                              "QUICK_STOP_ACTIVE", "FAULT_REACTION_ACTIVE", "FAULT"]),
       cw=st.sampled_from([0x0, 0x2, 0x6, 0x7, 0xF, 0x8F, 0x10F, 0x1F, 0x80, 0x106]) | st.integers(0, 0xFFFF),
       mode=st.sampled_from([8, 1, 0, 3]), own_mode=st.sampled_from([8, 1]), halt=st.booleans(),
       target=st.integers(-2**31, 2**31 - 1), velocity_offset=st.integers(-2**31, 2**31 - 1),
       torque_offset=st.integers(-2**15, 2**15 - 1), q_ref=st.floats(-4.0, 4.0),
       qs_option=st.sampled_from([0, 1, 2, 5, 6]), small_target=st.integers(-200000, 200000))
def test_a_sync_begin_in_the_core_is_the_python_begin(state, cw, mode, own_mode, halt, target, velocity_offset,
                                                      torque_offset, q_ref, qs_option, small_target):
    """JointDriveNode.on_sync_begin, with the core (steady SYNCs) and without: the drive's state
    after it agrees bit for bit, whatever the controlword, mode and targets."""
    from spacearm.base.canopen import od
    from spacearm.base.canopen.cia402_defs import State
    after = []
    for use_core in (True, False):
        drive = _drive()
        drive.state, drive.mode, drive.halt, drive.q_ref = State[state], own_mode, halt, q_ref
        drive.put(od.QUICK_STOP_OPTION, 0, qs_option)
        for index, value in ((od.CONTROLWORD, cw), (od.MODES_OF_OPERATION, mode), (od.TORQUE_OFFSET, torque_offset),
                             (od.TARGET_POSITION, target if target % 2 else small_target),
                             (od.VELOCITY_OFFSET, velocity_offset)):
            drive.put(index, 0, value)
        with core_switched(use_core):
            drive.on_sync_begin(0.02)
        after.append(repr({name: getattr(drive, name) for name in DRIVE_FIELDS}) + repr(drive.joint.max_motor_torque))
    assert after[0] == after[1]


@needs_core
@settings(max_examples=300, deadline=None)
@given(cw=st.sampled_from([0x0F, 0x1F, 0x3F, 0x10F]), q_ref=st.floats(-3.0, 3.0), delta=st.floats(-0.05, 0.05),
       velocity_offset=st.integers(-10**6, 10**6), limits=st.booleans(), halt=st.booleans())
def test_a_csp_sync_begin_in_operation_is_the_python_begin(cw, q_ref, delta, velocity_offset, limits, halt):
    """In OPERATION ENABLED and CSP, targets near the reference: the interpolation's end point,
    its speed and the limit flag agree bit for bit (steps beyond the velocity limit and the
    software position limits included)."""
    from spacearm.base.canopen import od
    from spacearm.base.canopen.cia402_defs import State
    after = []
    for use_core in (True, False):
        drive = _drive()
        k = drive._settings()[0]
        drive.state, drive.mode, drive.halt, drive.q_ref = State.OPERATION_ENABLED, od.MODE_CSP, halt, q_ref
        if limits:
            drive.put(od.SOFTWARE_POSITION_LIMIT, 1, round((q_ref - 0.01) * k))
            drive.put(od.SOFTWARE_POSITION_LIMIT, 2, round((q_ref + 0.01) * k))
        for index, value in ((od.CONTROLWORD, cw), (od.MODES_OF_OPERATION, od.MODE_CSP), (od.TORQUE_OFFSET, 100),
                             (od.TARGET_POSITION, round((q_ref + delta) * k)), (od.VELOCITY_OFFSET, velocity_offset)):
            drive.put(index, 0, value)
        with core_switched(use_core):
            drive.on_sync_begin(0.02)
        after.append(repr({name: getattr(drive, name) for name in DRIVE_FIELDS}))
    assert after[0] == after[1]


ops = st.lists(st.one_of(
    st.tuples(st.just("write"), st.lists(st.one_of(st.integers(-2**33, 2**33), st.integers(-3, 3), st.booleans()),
                                         min_size=4, max_size=4)),
    st.tuples(st.just("put"), st.integers(0, 3)), st.tuples(st.just("param"), st.integers(0, 3)),
    st.tuples(st.just("reset"), st.just(0))), max_size=12)


@needs_core
@settings(max_examples=300, deadline=None)
@given(ops)
def test_cyclic_writes_in_the_core_are_the_python_writes(operations):
    """od_cyclic.CyclicObjects.write with the core and without, over a sequence of writes (equal
    values again, bools, values that do not fit), someone else's put(), param() reads and
    resets: the same stored bytes, the same param() cache and epoch, the same errors."""
    from spacearm.base.canopen import od
    from spacearm.firmware_sim.od_cyclic import CyclicObjects
    objects = [(od.POSITION_ACTUAL, 0), (od.TORQUE_ACTUAL, 0), (od.STATUSWORD, 0), (od.MODES_OF_OPERATION_DISPLAY, 0)]
    traces = []
    for use_core in (True, False):
        drive = _drive()
        layout = CyclicObjects(drive, objects)
        epoch = drive._params.epoch       # the drive is reused: its epoch counts on from here
        trace = []
        with core_switched(use_core):
            for op, arg in operations:
                if op == "write":
                    try:
                        layout.write(arg)
                        trace.append("ok")
                    except ValueError as exc:
                        trace.append(str(exc))
                elif op == "put":
                    drive.put(*objects[arg], 1)
                elif op == "param":
                    trace.append(drive.param(*objects[arg]))
                else:
                    drive.power_on()
                trace.append(([drive.local.data_store.get(i, {}).get(s) for i, s in objects], dict(drive._params),
                              drive._params.epoch - epoch))
        traces.append(repr(trace))
    assert traces[0] == traces[1]


def _offset_of(drive, cob: int, index: int) -> int | None:
    offset = 0
    for mapped, _, size in drive.pdo_engine.rpdos[cob].entries:
        if mapped == index:
            return offset
        offset += size
    return None


@needs_core
@settings(max_examples=200, deadline=None)
@given(frames=st.lists(st.tuples(st.integers(0, 7), st.binary(min_size=0, max_size=8)), max_size=10),
       modes=st.lists(st.sampled_from([8, 1, 3, 0, -1]), min_size=10, max_size=10))
def test_rpdos_in_the_core_are_stored_as_python_stores_them(frames, modes):
    """PdoEngine.on_rpdo with the core and without: frames of any length to each RPDO (modes of
    operation the drive refuses among them): the same stored bytes, param() cache, malformed
    count and EMCY count."""
    from spacearm.base.canopen import od
    traces = []
    for use_core in (True, False):
        drive = _drive()
        drive.nmt_state = od.NMT_STATE_OPERATIONAL
        cobs = sorted(drive.rpdo_cob_ids())
        drive.param(od.TARGET_POSITION)
        counts = drive.stats.malformed, drive.stats.emcy_sent    # the drive is reused: counted from here
        trace = []
        with core_switched(use_core):
            for n, (which, data) in enumerate(frames):
                cob = cobs[which % len(cobs)]
                at = _offset_of(drive, cob, od.MODES_OF_OPERATION)
                if at is not None and len(data) > at and which % 2:     # a mode the drive may refuse
                    data = data[:at] + modes[n].to_bytes(1, "little", signed=True) + data[at + 1:]
                drive.on_rpdo(cob, data)
                trace.append((repr(sorted((i, sorted(v.items())) for i, v in drive.local.data_store.items())),
                              dict(drive._params), drive.stats.malformed - counts[0],
                              drive.stats.emcy_sent - counts[1]))
        traces.append(repr(trace))
    assert traces[0] == traces[1]


@needs_core
@settings(max_examples=100, deadline=None)
@given(types=st.lists(st.sampled_from([0, 1, 2, 3, 240, 241, 254, 255]), min_size=3, max_size=3),
       syncs=st.integers(1, 12), drop=st.integers(0, 2), corrupt=st.integers(0, 2), forget=st.booleans())
def test_tpdos_from_the_core_are_the_python_tpdos(types, syncs, drop, corrupt, forget):
    """PdoEngine.send_tpdos with the core and without, over several SYNCs: the same frames in
    the same order (synchronous types 0-240 due every type-th SYNC, others never), dropped and
    shortened frames of the fault switches, and a mapped object missing from the store."""
    from spacearm.base.canopen import od
    traces = []
    for use_core in (True, False):
        drive = _drive()
        drive.nmt_state = od.NMT_STATE_OPERATIONAL
        sent = []
        drive._send = lambda cob, data: sent.append((cob, data))
        drive._send_many = sent.extend
        drive.on_sync_begin(0.02)
        drive.on_sync_end(0.02)
        for pdo, kind in zip(drive.pdo_engine._tpdo_table(), types):
            pdo.transmission_type = kind
        drive.faults.drop_tx, drive.faults.corrupt_tx = drop, corrupt
        if forget:
            del drive.local.data_store[od.STATUSWORD][0]
        with core_switched(use_core):
            for _ in range(syncs):
                drive.send_tpdos()
        traces.append((sent, drive.stats.dropped_tx, drive.stats.corrupted_tx))
        drive.faults.drop_tx = drive.faults.corrupt_tx = 0
        drive.stats.dropped_tx = drive.stats.corrupted_tx = 0
        drive._send = drive._send_many = None
    assert traces[0] == traces[1]


@needs_core
@settings(max_examples=400, deadline=None)
@given(state=st.sampled_from(["SWITCH_ON_DISABLED", "READY_TO_SWITCH_ON", "SWITCHED_ON", "OPERATION_ENABLED",
                              "QUICK_STOP_ACTIVE", "FAULT_REACTION_ACTIVE", "FAULT"]),
       v_ref=st.sampled_from([0.0, 0.1, -0.2]), ramp=st.booleans(), brake_closing=st.sampled_from([0.0, 0.01, 0.029999999, 0.05]),
       error=st.sampled_from([0.0, 1e-4, 0.02, -0.5]), fe_time=st.sampled_from([0.0, 0.02, 0.5, 10.0]),
       temperature=st.sampled_from([25.0, 76.0, 90.0]), limit=st.booleans(), qs_option=st.sampled_from([0, 1, 2, 5]),
       q=st.floats(-3.0, 3.0), torque=st.floats(-100.0, 100.0))
def test_a_sync_end_in_the_core_is_the_python_end(state, v_ref, ramp, brake_closing, error, fe_time, temperature,
                                                  limit, qs_option, q, torque):
    """JointDriveNode.on_sync_end in CSP, with the core (a SYNC that changes no state) and
    without: the drive's state, the brake, the following error and the stored actual values
    agree bit for bit, and so do the SYNCs the core leaves to Python (a stop ending, a
    following-error timeout, over temperature: faults, EMCYs)."""
    from spacearm.base.canopen import od
    from spacearm.base.canopen.cia402_defs import State
    after = []
    for use_core in (True, False):
        drive = _drive()
        drive.on_sync_begin(0.02)
        j = drive.joint
        j.q, j.temperature, j.torque_reported = q, temperature, torque
        drive.state, drive.v_ref, drive._ramp_from_actual = State[state], v_ref, ramp
        drive.brake_closing, drive.q_ref, drive.fe_time, drive.limit_active = brake_closing, q + error, fe_time, limit
        drive._qs_option = qs_option
        emcy = drive.stats.emcy_sent
        with core_switched(use_core):
            drive.on_sync_end(0.02)
        after.append(repr(({name: getattr(drive, name) for name in DRIVE_FIELDS + ("brake_closing", "following_error")},
                           j.brake_engaged, sorted((i, sorted(v.items())) for i, v in drive.local.data_store.items()),
                           drive.stats.emcy_sent - emcy)))
    assert after[0] == after[1]


@needs_core
@settings(max_examples=300, deadline=None)
@given(error_code=st.sampled_from([0, 0x8611, 0xFFFF, 0x10000, -1]), mode=st.sampled_from([8, 1, 127, 128]),
       stale=st.booleans(), cached=st.booleans(), again=st.booleans(), q=st.floats(-3.0, 3.0),
       temperature=st.sampled_from([25.0, 76.0]), sw_bits=st.sampled_from(["OPERATION_ENABLED", "SWITCH_ON_DISABLED"]))
def test_a_sync_end_writing_its_values_in_the_core_is_the_python_end(error_code, mode, stale, cached, again, q,
                                                                     temperature, sw_bits):
    """drive_end_write (the SYNC end and the actual values' write in one core call) against the
    pure-Python SYNC end: the same stored bytes, param() cache and drive state, whether the
    store was just emptied (the core's write is then left to CyclicObjects.write), a value is
    cached by param(), the values repeat (nothing rewritten), or one does not fit its object
    (an error code or mode out of range: the same ValueError, the objects before it written)."""
    from spacearm.base.canopen import od
    from spacearm.base.canopen.cia402_defs import State
    after = []
    for use_core in (True, False):
        drive = _drive()
        drive.on_sync_begin(0.02)
        j = drive.joint
        j.q, j.temperature = q, temperature
        drive.state, drive.error_code, drive.mode = State[sw_bits], error_code, mode
        drive.q_ref = q
        if stale:
            drive.store_generation += 1
        if cached:
            drive.param(od.POSITION_ACTUAL)
        outcome = []
        with core_switched(use_core):
            for _ in range(2 if again else 1):
                try:
                    drive.on_sync_end(0.02)
                    outcome.append(None)
                except ValueError as exc:
                    outcome.append(str(exc))
        after.append(repr(({name: getattr(drive, name) for name in DRIVE_FIELDS + ("brake_closing", "following_error")},
                           j.brake_engaged, sorted((i, sorted(v.items())) for i, v in drive.local.data_store.items()),
                           sorted(drive._params.items()), outcome)))
        drive.error_code, drive.mode = 0, 8
    assert after[0] == after[1]
