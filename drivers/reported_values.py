"""What a device reported, by (index, sub), kept as the tuple a SYNC's burst decoded (issue 35).

A burst that brings every TPDO of a node in its layout's order (drivers/tpdo_burst.py) leaves
the node's values as one tuple in that order, `latest`; the cycle's readers (the joints' step
and state, the end effector's and F/T sensor's state) take them from it by position with a
reader compiled from the layout. Updating a dict keyed by (index, sub) with ~9 values per node
and reading them back by key (tuple keys hash anew on every lookup) cost ~1 us per joint a cycle.

The dict `values` stays the one view for everyone else: reading the attribute merges a pending
tuple into it first, so a frame decoded one by one, a node's values cleared at its boot-up or a
test's direct write always land after what came before, as when every burst updated the dict.
Everything that decodes or reads here runs under the network's lock (cyclic_io.py, health.py).
"""
from __future__ import annotations

from operator import itemgetter
from typing import Iterable


class ReportedValues:
    """The reported-values part of a device driver (devices.DeviceDriver)."""

    _values: dict
    latest: tuple | None            # the layout's TPDO values not yet merged into _values
    tpdo_keys: tuple                # (index, sub) of the layout's TPDO entries, TPDO by TPDO

    @property
    def values(self) -> dict[tuple[int, int], int]:
        """Every object the device reported, by (index, sub) (a mutable dict: tests write it)."""
        if self.latest is not None:
            self._merge_latest()
        return self._values

    def _merge_latest(self) -> None:
        self._values.update(zip(self.tpdo_keys, self.latest))
        self.latest = None

    def _use_tpdo_keys(self, tpdos: Iterable) -> None:
        """A new layout: a pending tuple is merged with the keys it was decoded for first."""
        if getattr(self, "latest", None) is not None:
            self._merge_latest()
        self.tpdo_keys = tuple((e.index, e.sub) for spec in tpdos for e in spec.entries)

    def tuple_reader(self, keys: Iterable[tuple[int, int]]) -> itemgetter | None:
        """These objects read from `latest` in one call (a tuple of them), or None where the
        layout maps one of them nowhere (the caller reads the dict). An object mapped twice is
        read where the dict's update would have left it: its last place."""
        keys = tuple(keys)
        at = {key: i for i, key in enumerate(self.tpdo_keys)}
        if len(keys) < 2 or not all(key in at for key in keys):
            return None
        return itemgetter(*(at[key] for key in keys))
