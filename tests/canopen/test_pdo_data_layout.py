"""The master's PDO data layout (issue 35) against the dict path it replaces: a joint's RPDOs
packed from its step's values (drivers/joint_rpdos.py) are the frames rpdo_frames() codes from
rpdo_values after the step; a burst's TPDOs kept as one tuple per node (drivers/reported_values.py)
give the states, steps and values dicts that decoding frame by frame into the dicts gives, and
whatever writes the dict afterwards (a frame one by one, a boot-up's clear, a test) wins."""
from __future__ import annotations

import random

from spacearm.base.canopen import od
from spacearm.base.config.bus import load_bus_config
from spacearm.drivers.network import ArmNetwork


def _nets(n=2):
    return [ArmNetwork("virtual:unused", load_bus_config()) for _ in range(n)]    # not connected


def _tpdo_frames(net, rng):
    frames = []
    for d in net.drivers.values():
        for spec in d.tpdos:
            data = bytearray(rng.randrange(256) for _ in range(spec.length))
            if spec.entries[0].index == od.STATUSWORD:     # a few real words: the states decode
                data[0:2] = rng.choice([0x0237, 0x0250, 0x0233, 0x0208, 0x0231]).to_bytes(2, "little")
            frames.append((spec.cob_id, bytes(data)))
    return frames


def _states(net):
    return ([vars(j.state()) for j in net.joints], vars(net.end_effector.state()), vars(net.ft.state()))


def test_rpdos_packed_from_the_step_are_the_frames_of_the_dict():
    net, = _nets(1)
    rng = random.Random(1501)
    joint = net.joints[0]
    swapped = [type(s)(s.kind, s.number, s.cob_id, list(reversed(s.entries))) for s in joint.rpdos]
    for layout in (joint.rpdos, swapped):
        joint.set_layout(layout, joint.tpdos)
        for _ in range(300):
            joint.target = rng.choice([None, 0.0, -0.0, rng.uniform(-4, 4), rng.uniform(-1e7, 1e7)])
            joint.velocity_ff = rng.choice([0.0, -0.0, rng.uniform(-2, 2), rng.uniform(-1e8, 1e8)])
            joint.torque_ff = rng.choice([0.0, -0.0, rng.uniform(-50, 50), rng.uniform(-1e7, 1e7)])
            joint.halt = rng.random() < 0.2
            joint.values[(od.STATUSWORD, 0)] = rng.choice([0x0237, 0x0250, 0x0233])
            joint.values[(od.POSITION_ACTUAL, 0)] = rng.randrange(-2 ** 31, 2 ** 31)
            rng.choice([joint.axis.enable, joint.axis.disable, joint.axis.quick_stop])()
            if rng.random() < 0.1:
                joint.set_mode(rng.choice([od.MODE_CSP, od.MODE_PROFILE_POSITION]))
            frames = joint.step_frames()
            assert frames == joint.rpdo_frames()


def test_a_burst_kept_as_tuples_reads_as_the_frames_decoded_one_by_one():
    rng = random.Random(1502)
    burst_net, frame_net = _nets()
    for round_ in range(60):
        frames = _tpdo_frames(burst_net, rng)
        if round_ % 7 == 3:
            rng.shuffle(frames)      # another order: the dicts updated, no tuple
        if round_ % 5 == 4:
            frames = frames[: rng.randrange(2, len(frames))]    # a loopback read cut short
        burst_net.network.listeners[0].on_frames(frames, 0.0)
        for can_id, data in frames:
            frame_net.network.listeners[0].on_frame(can_id, data, 0.0)
        assert _states(burst_net) == _states(frame_net)
        for a, b in zip(burst_net.joints, frame_net.joints):
            assert a.position == b.position
            assert a.step_frames() == b.step_frames()
        if round_ % 3 == 0:      # the dicts compared (which merges the tuples) only now and then
            assert ({n: dict(d.values) for n, d in burst_net.drivers.items()}
                    == {n: dict(d.values) for n, d in frame_net.drivers.items()})
    assert any(d.latest is not None for d in burst_net.drivers.values())     # the tuple path ran


def test_what_writes_the_dict_after_a_burst_wins_over_its_tuple():
    net, = _nets(1)
    rng = random.Random(1503)
    joint = net.joints[1]
    net.network.listeners[0].on_frames(_tpdo_frames(net, rng), 0.0)
    assert joint.latest is not None
    joint.values[(od.POSITION_ACTUAL, 0)] = 12345          # a test's (or anyone's) direct write
    assert joint.latest is None and joint.state().position == 12345 / joint.k
    net.network.listeners[0].on_frames(_tpdo_frames(net, rng), 0.0)
    spec = joint.tpdos[0]
    data = bytes(rng.randrange(256) for _ in range(spec.length))
    net.network.listeners[0].on_frame(spec.cob_id, data, 0.0)     # one frame after the burst
    reference, = _nets(1)
    reference.joints[1].decode(spec, data)
    assert joint.value(od.STATUSWORD) == reference.joints[1].value(od.STATUSWORD)
    net.network.listeners[0].on_frames(_tpdo_frames(net, rng), 0.0)
    joint.values.clear()                                    # a boot-up: nothing reported any more
    assert vars(joint.state()) == vars(joint._state_of_defaults()) and joint.state().position == 0.0


def test_a_new_layout_merges_the_tuple_of_the_old_one_first():
    net, = _nets(1)
    joint = net.joints[0]
    frames = _tpdo_frames(net, random.Random(1504))
    net.network.listeners[0].on_frames(frames, 0.0)
    before = dict(net.joints[0]._values), joint.latest
    expected = _nets(1)[0]
    for can_id, data in frames:
        expected.network.listeners[0].on_frame(can_id, data, 0.0)
    swapped = [type(s)(s.kind, s.number, s.cob_id, list(reversed(s.entries))) for s in joint.tpdos]
    joint.set_layout(joint.rpdos, swapped)
    assert before[1] is not None and joint.latest is None
    assert joint._values == expected.joints[0].values
    net.network.listeners[0].on_frames(frames, 0.0)         # the old plan: its keys are no longer the layout's
    assert joint.latest is None


def test_a_joints_reading_is_its_states_four_values_and_read_gives_them_instead():
    net, = _nets(1)
    rng = random.Random(1505)
    for round_ in range(40):
        frames = _tpdo_frames(net, rng)
        if round_ % 4 == 1:
            rng.shuffle(frames)      # the dicts' path
        net.network.listeners[0].on_frames(frames, 0.0)
        for joint in net.joints:
            state = joint.state()
            assert joint.reading() == (state.position, state.velocity, state.torque, state.state)
        arm = net.read(True, nodes=False, joints=False)
        assert arm.joints == [] and arm.readings == [j.reading() for j in net.joints]
        assert net.read(True, nodes=False).readings is None

