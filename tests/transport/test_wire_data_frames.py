"""The loopback bus's burst encoding (wire.encode_data_frames) is each frame's FRAME record
(encode_data_frame) joined, and refuses what encode_data_frame refuses, with its words."""
import random

import can
import pytest

from spacearm.base.transport import wire
from spacearm.base.transport.loopback import LoopbackBus


def test_a_burst_is_its_frames_records_joined():
    rng = random.Random(35)
    for _ in range(500):
        frames = [(rng.randrange(0x800), bytes(rng.randrange(256) for _ in range(rng.randrange(9))))
                  for _ in range(rng.randrange(40))]
        joined = b"".join([wire.encode_data_frame(can_id, data) for can_id, data in frames])
        assert wire.encode_data_frames(frames) == joined
        # and the stream decodes back to the same frames
        burst = []
        assert wire.decode_stream(bytearray(joined), 0.0, None, lambda f, t: burst.extend(f)) == []
        assert burst == frames


@pytest.mark.parametrize("bad", [(0x800, b""), (-1, b"\x01"), (0x123, bytes(9))])
def test_a_frame_no_controller_could_send_is_refused_as_one_frame_is(bad):
    with pytest.raises(ValueError) as one:
        wire.encode_data_frame(*bad)
    with pytest.raises(ValueError) as burst:
        wire.encode_data_frames([(0x181, b"\x00"), bad, (0x182, b"")])
    assert str(burst.value) == str(one.value)
    bus = object.__new__(LoopbackBus)     # the refusal comes before any connection is used
    bus._closed = False
    try:
        with pytest.raises(can.CanOperationError, match="cannot send: frame"):
            bus.send_frames([bad])
    finally:
        bus._closed = bus._is_shutdown = True     # nothing to shut down at collection
