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
        self._values: list = [None] * len(layout)
        self._stored: list = [None] * len(layout)
        self._generation = -1
        self._entries: list = []      # the store's dict of each object's index, while the store lasts

    def write(self, values) -> None:
        """The objects' new values, in the order given at construction."""
        node = self._node
        store = node.local.data_store
        params = node._params
        if self._generation != node.store_generation:    # a reset emptied the store
            self._generation, self._entries = node.store_generation, [None] * len(self._layout)
        entries, last_values, last_stored = self._entries, self._values, self._stored
        for i, value in enumerate(values):
            index, sub, pack = self._layout[i]
            entry = entries[i]
            if entry is None:
                entry = entries[i] = store.setdefault(index, {})
            elif value == last_values[i] and entry.get(sub) is last_stored[i]:
                continue
            try:
                data = pack(int(value))
            except struct.error:
                raise ValueError(f"0x{index:04X}:{sub:02X}: {value!r} does not fit {pack.__self__.format}") from None
            entry[sub] = data
            if params and (index, sub) in params:
                del params[(index, sub)]
            last_values[i], last_stored[i] = value, data
