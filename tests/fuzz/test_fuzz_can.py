"""Random and malformed CAN frames into every simulated node type and into the controller's
drivers: nothing raises, nothing moves, errors are counted, and everyone still answers a
valid request afterwards. SDO with bad command specifiers and segmented transfers that
never finish, in both directions."""
from __future__ import annotations

import struct
import threading
import time
import uuid

import can
import numpy as np
import pytest
from hypothesis import given, strategies as st

from spacearm.base.canopen import od
from tests.fuzz.conftest import CaseCounter

NODE_IDS = {"joint": 1, "end_effector": 16, "ft_sensor": 17}

# COB-IDs the bus uses, plus anything: NMT, SYNC, EMCY, TPDO/RPDO 1-4, SDO rx/tx, heartbeat.
SERVICE_BASES = [0x000, 0x080, 0x180, 0x200, 0x280, 0x300, 0x380, 0x400, 0x480, 0x500, 0x580,
                 0x600, 0x700]
frame_ids = st.one_of(
    st.sampled_from(SERVICE_BASES).flatmap(lambda b: st.integers(b, b + 0x7F)),
    st.integers(0, 0x7FF))
frames = st.tuples(frame_ids, st.binary(min_size=0, max_size=8),
                   st.sampled_from(["std", "std", "std", "std", "remote", "extended", "error"]))


def message(cid: int, data: bytes, kind: str) -> can.Message:
    return can.Message(arbitration_id=cid if kind != "extended" else cid | 0x1000_0000, data=data,
                       is_extended_id=kind == "extended", is_remote_frame=kind == "remote",
                       is_error_frame=kind == "error", dlc=len(data))


def not_motion(cid: int, data: bytes) -> bool:
    """Frames that are not SYNC (SYNC advances the physics; moving needs enabled drives anyway)."""
    return cid != od.SYNC_COB_ID_DEFAULT


@pytest.fixture(scope="module")
def sim():
    from spacearm.firmware_sim.runner import start_simulator
    s = start_simulator(f"virtual:fuzz-{uuid.uuid4().hex[:8]}",
                        plant="configs/plant/oru_testbed_nominal.toml", control_node_id=None)
    time.sleep(0.2)
    yield s
    s.stop()


def plant_q(sim) -> np.ndarray:
    return np.array([j.q for j in sim.plant.joints])


@given(st.lists(frames, min_size=1, max_size=20))
def test_random_frames_into_the_simulated_nodes(sim, batch):
    CaseCounter.hit("can_frames_into_nodes")
    q0 = plant_q(sim)
    before = sim.stats.internal_errors
    for cid, data, kind in batch:
        sim._route(message(cid, data, kind))            # raises if a node mishandles a frame
    assert sim.stats.internal_errors == before
    # nothing moved: drives come up disabled with brakes on, and random frames do not enable them
    assert np.allclose(plant_q(sim), q0, atol=1e-6)


SDO_CCS = st.integers(0, 255)


@given(node=st.sampled_from(sorted(NODE_IDS.values())), cs=SDO_CCS,
       index=st.integers(0, 0xFFFF), sub=st.integers(0, 255), payload=st.binary(min_size=0, max_size=4),
       length=st.integers(0, 8))
def test_sdo_with_any_command_specifier_is_answered_or_ignored(sim, node, cs, index, sub, payload, length):
    CaseCounter.hit("sdo_bad_command_specifiers")
    data = (bytes([cs]) + struct.pack("<HB", index, sub) + payload.ljust(4, b"\0"))[:length]
    sim._route(message(od.SDO_RX_BASE + node, data, "std"))
    # abort whatever half-open transfer this left behind, like a master would
    sim._route(message(od.SDO_RX_BASE + node, bytes([0x80, 0, 0, 0, 0, 0, 0, 0]), "std"))


def test_sim_node_recovers_from_a_segmented_download_that_never_finishes(sim, open_bus_pair):
    """Initiate a segmented download (size 100), never send the segments, then a normal
    expedited upload must still be answered."""
    master = open_bus_pair
    node = NODE_IDS["joint"]
    initiate = bytes([0x21]) + struct.pack("<HB", od.DEVICE_NAME, 0) + struct.pack("<I", 100)
    master.send(can.Message(arbitration_id=od.SDO_RX_BASE + node, data=initiate, is_extended_id=False))
    reply = _recv_from(master, od.SDO_TX_BASE + node)
    assert reply is not None          # initiate answered (or aborted: DEVICE_NAME is const)
    upload = bytes([0x40]) + struct.pack("<HB", od.DEVICE_TYPE, 0) + bytes(4)
    master.send(can.Message(arbitration_id=od.SDO_RX_BASE + node, data=upload, is_extended_id=False))
    reply = _recv_from(master, od.SDO_TX_BASE + node)
    assert reply is not None and reply.data[0] & 0xE0 in (0x40, 0x80), reply


@pytest.fixture
def open_bus_pair(sim):
    from spacearm.base.transport import open_bus
    bus = open_bus(sim.bus_spec) if hasattr(sim, "bus_spec") else None
    if bus is None:
        pytest.skip("simulator does not expose its bus spec")
    yield bus
    bus.shutdown()


def _recv_from(bus, cob: int, timeout: float = 1.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        msg = bus.recv(0.05)
        if msg is not None and msg.arbitration_id == cob:
            return msg
    return None


# ------------------------------------------------------------------ controller side
@pytest.fixture(scope="module")
def arm():
    """An ArmNetwork on a bus with no nodes: every frame it sees comes from the fuzzer."""
    from spacearm.drivers.network import ArmNetwork
    net = ArmNetwork(f"virtual:fuzz-ctl-{uuid.uuid4().hex[:8]}").connect()
    yield net
    net.close()


@given(st.lists(frames, min_size=1, max_size=30))
def test_random_frames_into_the_controller_drivers(arm, batch):
    CaseCounter.hit("can_frames_into_controller")
    from spacearm.drivers.network import _Listener
    listener = next(x for x in arm.network.listeners if isinstance(x, _Listener))
    before = arm.stats.callback_errors
    for cid, data, kind in batch:
        listener.on_message_received(message(cid, data, kind))   # the bus's real entry point
    state = arm.read()                                # the values stay readable
    arm.poll_events()                                 # events are plain values
    assert len(state.joints) == 6
    assert arm.stats.callback_errors == before


class FakeNode(threading.Thread):
    """Answers every SDO request to node 1 with `reply(request)` (None: silence)."""

    def __init__(self, spec: str, reply):
        super().__init__(daemon=True)
        from spacearm.base.transport import open_bus
        self.bus = open_bus(spec)
        self.reply = reply
        self.stop = threading.Event()

    def run(self):
        while not self.stop.is_set():
            msg = self.bus.recv(0.02)
            if msg is not None and msg.arbitration_id == od.SDO_RX_BASE + 1:
                out = self.reply(bytes(msg.data))
                if out is not None:
                    self.bus.send(can.Message(arbitration_id=od.SDO_TX_BASE + 1, data=out, is_extended_id=False))

    def close(self):
        self.stop.set()
        self.join(1)
        self.bus.shutdown()


@pytest.fixture(scope="module")
def sdo_target():
    """A controller network and a fake node whose SDO answers the test chooses."""
    from spacearm.drivers.network import ArmNetwork
    spec = f"virtual:fuzz-sdo-{uuid.uuid4().hex[:8]}"
    holder = {"reply": lambda req: None}
    node = FakeNode(spec, lambda req: holder["reply"](req))
    node.start()
    net = ArmNetwork(spec).connect()
    for remote in net.remote.values():
        remote.sdo.RESPONSE_TIMEOUT = 0.05
    yield net, holder
    net.close()
    node.close()


@given(answer=st.binary(min_size=0, max_size=8))
def test_controller_sdo_read_with_garbage_answers_fails_cleanly(sdo_target, answer):
    from spacearm.drivers.errors import DriverError
    CaseCounter.hit("sdo_garbage_answers_into_controller")
    net, holder = sdo_target
    holder["reply"] = lambda req: answer
    t0 = time.monotonic()
    try:
        net.sdo_read("joint_1", od.DEVICE_TYPE, 0)
    except DriverError as exc:
        assert str(exc)
    assert time.monotonic() - t0 < 2.0


def test_controller_segmented_upload_that_never_finishes_times_out_cleanly(sdo_target):
    from spacearm.drivers.errors import DriverError
    net, holder = sdo_target
    # initiate a segmented upload of 100 bytes, then never send a segment
    holder["reply"] = lambda req: (bytes([0x41]) + req[1:4] + struct.pack("<I", 100)) if req[0] & 0xE0 == 0x40 else None
    t0 = time.monotonic()
    with pytest.raises(DriverError):
        net.sdo_read("joint_1", od.DEVICE_NAME, 0)
    assert time.monotonic() - t0 < 2.0
