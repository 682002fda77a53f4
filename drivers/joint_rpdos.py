"""A joint's RPDOs packed straight from the values its step just computed (issue 35).

Packing from the rpdo_values dict cost a lookup keyed by (index, sub) per mapped object
(`pack(*map(get, keys, zeros))`: ~0.7 us an RPDO); the step has the controlword and the three
set-points in hand. The layout is compiled once into one function per driver, as a struct
format is: each RPDO's struct.pack called with the step's values where the layout maps them,
and the dict's value (0 where absent, as PdoCodec.encode) for any other object. The same
values in the same order as packing from the dict after the step wrote them: the same bytes.
"""
from __future__ import annotations

from typing import Callable, Sequence

from spacearm.base.canopen import od

# the objects JointDriver.step writes every cycle, in pack_rpdos' argument order
STEP_OBJECTS = {(od.CONTROLWORD, 0): "cw", (od.TARGET_POSITION, 0): "position",
                (od.VELOCITY_OFFSET, 0): "velocity", (od.TORQUE_OFFSET, 0): "torque"}

PackRpdos = Callable[[int, int, int, int, Callable], list]


def compile_rpdo_packer(codecs: Sequence) -> PackRpdos | None:
    """`pack_rpdos(cw, position, velocity, torque, get) -> [(cob_id, payload), ...]` for these
    compiled RPDO codecs (devices.PdoCodec), `get` the rpdo_values dict's get; None where a
    codec codes entry by entry (no struct: rpdo_frames() then)."""
    if any(codec.struct is None for codec in codecs):
        return None
    namespace: dict = {}
    frames = []
    for n, codec in enumerate(codecs):
        namespace[f"pack{n}"] = codec.struct.pack
        args = []
        for m, key in enumerate(codec.keys):
            if key in STEP_OBJECTS:
                args.append(STEP_OBJECTS[key])
            else:
                namespace[f"key{n}_{m}"] = key
                args.append(f"get(key{n}_{m}, 0)")
        frames.append(f"({codec.cob_id}, pack{n}({', '.join(args)}))")
    # generated as namedtuple and dataclasses generate theirs: a call with the values as
    # arguments, no loop, no lookup by key for what the step computed
    source = f"def pack_rpdos(cw, position, velocity, torque, get):\n    return [{', '.join(frames)}]\n"
    exec(compile(source, "<joint_rpdos>", "exec"), namespace)
    return namespace["pack_rpdos"]
