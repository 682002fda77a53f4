"""The objects a device writes into its own object dictionary every SYNC (actual values,
status words), compiled once: each object's struct from the EDS, stored straight into the
node's data store; an object whose value did not change since the last write, and whose
stored bytes are still the very ones written then, is not written again.

Same result as SimNode.put for each object (same bytes, the param() cache dropped on a
write, the same one-line error for a value that does not fit): a drive updates ten objects a
SYNC and most hold still, so the generic put (a cache lookup, a type test and two dict
operations per object) was a sixth of the simulator's CPU (issue 35).
"""
from __future__ import annotations

import struct

from spacearm.firmware_sim import simcore

_UNSET = object()      # the last value of an object not written since the store was emptied


class CyclicObjects:
    def __init__(self, node, objects: list[tuple[int, int]]):
        self._node = node
        layout = []
        for index, sub in objects:
            obj, codec, integer = node._codec(index, sub)
            if codec is None or not integer:
                raise ValueError(f"0x{index:04X}:{sub:02X}: not an integer object, written with put()")
            layout.append((index, sub, codec.pack))
        self._layout = tuple(layout)
        self._values: list = [_UNSET] * len(layout)
        self._stored: list = [None] * len(layout)
        self._generation = -1
        self._entries: list = []      # the store's dict of each object's index, while the store lasts
        # the compiled core's layout (_simcore.c cyclic_write): (sub, bytes, signed, cache key)
        self._specs = tuple((sub, pack.__self__.size, pack.__self__.format[-1].islower(), (index, sub))
                            for index, sub, pack in layout)

    def write(self, values) -> None:
        """The objects' new values, in the order given at construction."""
        node = self._node
        params = node._params
        if self._generation != node.store_generation:    # a reset emptied the store: write every object
            store = node.local.data_store
            self._generation = node.store_generation
            self._entries = [store.setdefault(index, {}) for index, _, _ in self._layout]
            self._values[:] = [_UNSET] * len(self._layout)
        start = 0
        core = simcore.core
        if core is not None:
            start = core.cyclic_write(self._specs, values, self._entries, self._values, self._stored, params, 0)
            if start == len(values):
                return
        self.write_from(values, start)

    def write_from(self, values, start: int) -> None:
        """write()'s loop in Python from object `start` (where the core stopped), the store
        generation current."""
        params = self._node._params
        entries, last_values, last_stored = self._entries, self._values, self._stored
        for i in range(start, len(values)):      # where the core stopped, or all of them
            value = values[i]
            index, sub, pack = self._layout[i]
            entry = entries[i]
            if value == last_values[i] and entry.get(sub) is last_stored[i]:
                continue
            try:
                data = pack(int(value))
            except struct.error:
                raise ValueError(f"0x{index:04X}:{sub:02X}: {value!r} does not fit {pack.__self__.format}") from None
            entry[sub] = data
            if params and (index, sub) in params:
                del params[(index, sub)]
            last_values[i], last_stored[i] = value, data
