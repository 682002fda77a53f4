"""The drivers' per-cycle shortcuts (issue 35) against what they replace: RPDOs packed from
rpdo_packs as rpdo_frames() codes them, the commands applied per field as per joint, the
set-point clamps as min/max, the end effector's and F/T sensor's states as before."""
from __future__ import annotations

import random

from spacearm.base.canopen import od
from spacearm.base.config.bus import load_bus_config
from spacearm.drivers.cyclic_io import ArmCommand
from spacearm.drivers.devices import EeState
from spacearm.drivers.network import ArmNetwork


def _packed(driver):
    get = driver.rpdo_values.get
    return [(cob, pack(*map(get, keys, zeros))) for cob, pack, keys, zeros in driver.rpdo_packs]


def test_rpdo_packs_give_the_frames_rpdo_frames_gives_and_follow_a_new_layout():
    net = ArmNetwork("virtual:unused", load_bus_config())
    rng = random.Random(41)
    for driver in net.drivers.values():
        assert driver.rpdo_packs is not None
        for _ in range(20):
            for spec in driver.rpdos:
                for e in spec.entries:
                    if rng.random() < 0.8:     # some objects missing: encoded as 0 both ways
                        bits = e.size * 8
                        signed = e.var.data_type in (2, 3, 4)
                        driver.rpdo_values[(e.index, e.sub)] = (rng.randrange(-2 ** (bits - 1), 2 ** (bits - 1))
                                                                if signed else rng.randrange(2 ** bits))
            assert _packed(driver) == driver.rpdo_frames()
            driver.rpdo_values.clear()
    driver = net.drivers["joint_1"]
    swapped = [type(s)(s.kind, s.number, s.cob_id, list(reversed(s.entries))) for s in driver.rpdos]
    driver.set_layout(swapped, driver.tpdos)
    driver.rpdo_values.update({(e.index, e.sub): 1 + i for i, e in enumerate(swapped[0].entries)})
    assert _packed(driver) == driver.rpdo_frames()
    assert [keys for _, _, keys, _ in driver.rpdo_packs] == [tuple((e.index, e.sub) for e in s.entries)
                                                              for s in swapped]


def _apply_reference(joints, c: ArmCommand) -> None:
    """CyclicIO._apply before issue 35: per joint, each field tested against its sequence."""
    for i, j in enumerate(joints):
        if c.joint_positions is not None and i < len(c.joint_positions) and c.joint_positions[i] is not None:
            j.target = float(c.joint_positions[i])
        if c.joint_velocities is not None and i < len(c.joint_velocities):
            j.velocity_ff = float(c.joint_velocities[i])
        if c.joint_torques is not None and i < len(c.joint_torques):
            j.torque_ff = float(c.joint_torques[i])


def test_commands_are_applied_as_joint_by_joint():
    nets = [ArmNetwork("virtual:unused", load_bus_config()) for _ in range(2)]
    rng = random.Random(42)
    n = len(nets[0].joints)

    def sequence(none_ok):
        if rng.random() < 0.2:
            return None
        return [None if none_ok and rng.random() < 0.3 else rng.uniform(-3, 3)
                for _ in range(rng.randrange(0, n + 2))]

    for _ in range(200):
        command = ArmCommand(sequence(True), sequence(False), sequence(False))
        nets[0]._apply(command)
        _apply_reference(nets[1].joints, command)
        assert ([(j.target, j.velocity_ff, j.torque_ff) for j in nets[0].joints]
                == [(j.target, j.velocity_ff, j.torque_ff) for j in nets[1].joints])


def test_set_points_are_clamped_to_the_objects_ranges_as_min_max_did():
    net = ArmNetwork("virtual:unused", load_bus_config())
    joint = net.joints[0]
    i32 = (-2 ** 31, 2 ** 31 - 1)
    rng = random.Random(43)
    for _ in range(300):
        joint.target = rng.choice([rng.uniform(-1e3, 1e3), rng.uniform(-1e7, 1e7), 0.0])
        joint.velocity_ff = rng.choice([rng.uniform(-1e2, 1e2), rng.uniform(-1e7, 1e7)])
        joint.torque_ff = rng.choice([rng.uniform(-1e2, 1e2), rng.uniform(-1e6, 1e6)])
        joint.values[(od.STATUSWORD, 0)] = 0x0027            # operation enabled
        joint.axis.enable()
        joint.step()
        rpdo, k = joint.rpdo_values, joint.k
        target = joint.target if joint.target is not None else joint._hold
        assert rpdo[(od.TARGET_POSITION, 0)] == max(i32[0], min(i32[1], round(target * k)))
        assert rpdo[(od.VELOCITY_OFFSET, 0)] == max(i32[0], min(i32[1], round(joint.velocity_ff * k)))
        assert rpdo[(od.TORQUE_OFFSET, 0)] == max(-32768, min(32767, round(joint.torque_ff / joint.rated_joint_torque
                                                                           * 1000)))


def test_end_effector_and_ft_states_are_what_they_were():
    net = ArmNetwork("virtual:unused", load_bus_config())
    ee, ft = net.end_effector, net.ft
    rng = random.Random(44)
    assert ee.state().state is EeState.UNKNOWN and ft.state().force == (0.0, 0.0, 0.0)     # nothing received
    for _ in range(100):
        for driver in (ee, ft):
            for spec in driver.tpdos:
                driver.decode(spec, bytes(rng.randrange(256) for _ in range(spec.length)))
        raw = rng.choice([rng.randrange(0, 12), rng.randrange(256)])
        ee.values[(od.EE_STATE, 0)] = raw
        state = ee.state()
        assert state.state is (EeState(raw) if raw in EeState._value2member_map_ else EeState.UNKNOWN)
        assert (state.grip, state.screw_torque, state.screw_turns, state.fault_code) == (
            ee.value(od.EE_GRIP_POSITION) / 1000.0, ee.value(od.EE_SCREW_TORQUE) / 1000.0,
            ee.value(od.EE_SCREW_TURNS) / 1000.0, ee.value(od.EE_FAULT_CODE))
        s, v = ft.cfg.ft, [ft.value(od.FT_VALUES, i) for i in range(1, 7)]
        got = ft.state()
        assert got.force == tuple(x / s.force_counts_per_n for x in v[:3])
        assert got.torque == tuple(x / s.torque_counts_per_nm for x in v[3:])


def test_the_cycles_array_shortcuts_are_what_numpy_gives():
    """core._zeros_as is np.zeros_like, np.count_nonzero is ndarray.any() as a truth value
    (supervision.py), hardware's end-effector state is EndEffectorState(name.lower())."""
    import numpy as np
    from spacearm.controller.cycle import EndEffectorState
    from spacearm.controller.daemon.core import _zeros_as
    from spacearm.controller.daemon.hardware import _end_effector_state
    from spacearm.drivers.devices import EndEffectorState as DriverEeState
    for q in (np.arange(6.0), np.array([], float), np.arange(6), np.float32([1, 2]), np.arange(12.0)[::2], [1.0, 2.0]):
        z, reference = _zeros_as(q), np.zeros_like(q)
        assert (type(z), z.dtype, z.shape, z.tobytes()) == (type(reference), reference.dtype, reference.shape,
                                                            reference.tobytes())
    rng = np.random.default_rng(45)
    for _ in range(200):
        a = rng.choice([0.0, -0.0, 1.0, np.nan, np.inf], size=rng.integers(0, 8))
        assert bool(np.count_nonzero(a)) == bool(a.any())
        assert bool(np.count_nonzero(a > 0.5)) == bool((a > 0.5).any())
    assert _end_effector_state(None) is EndEffectorState.NONE
    for raw in EeState:
        assert _end_effector_state(DriverEeState("ee", 9, raw)) is EndEffectorState(raw.name.lower())


def test_joint_state_read_in_one_call_is_the_state_of_the_lookups():
    """JointDriver.state() once every object is reported (one itemgetter call) against the
    lookups it replaces (_state_of_defaults), field for field and in the same order; before
    the first TPDO, and with an object missing, the lookups themselves."""
    net = ArmNetwork("virtual:unused", load_bus_config())
    rng = random.Random(43)
    for driver in net.joints:
        assert driver._reported is not None       # the default layout maps every object it reads
        assert vars(driver.state()) == vars(driver._state_of_defaults())    # nothing reported yet
        mapped = [(e.index, e.sub, e) for spec in driver.tpdos for e in spec.entries]
        for _ in range(50):
            for index, sub, e in mapped:
                bits = e.size * 8
                driver.values[(index, sub)] = rng.randrange(2 ** bits) - (2 ** (bits - 1) if rng.random() < 0.5 else 0)
            driver.values[(od.STATUSWORD, 0)] = rng.choice([0x0237, 0x0250, 0x0208, 0x0231, 0x0233, 0x0217])
            fast, looked_up = driver.state(), driver._state_of_defaults()
            assert list(vars(fast).items()) == list(vars(looked_up).items())
        del driver.values[(od.POSITION_ACTUAL, 0)]
        assert vars(driver.state()) == vars(driver._state_of_defaults())
        assert driver.state().position == 0.0
