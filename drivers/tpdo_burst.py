"""A burst of TPDOs (a SYNC's answers, handed over in one call by the bus) decoded node by node:
one precompiled struct per node for the burst's layout, instead of a route lookup, a length
check, an unpack and a set insert per frame (issue 35: the master's TPDO decode was ~40 us of
a lockstep cycle, 22 frames of 8 nodes).

A plan is fixed per sequence of COB-IDs (a SYNC's burst has the same one every cycle) from the
routes built with the network (cyclic_io.TpdoRoute); it decodes the same values into the same
dicts in the same order as the per-frame path, which stays for everything a plan does not
cover: a frame that is no compiled TPDO, a COB-ID twice in one burst, a frame whose length is
not its PDO's (short ones are malformed there, long ones decoded from their start).
"""
from __future__ import annotations

import struct
from operator import itemgetter

first, second = itemgetter(0), itemgetter(1)

# A loopback read may cut a cycle's frames anywhere: plans (and "no plan") per sequence are
# kept, and forgotten all at once beyond this many sequences so odd traffic cannot grow it.
MAX_PLANS = 256


class NodeSlice:
    """One node's part of a burst: its values dict's keys in burst order and one struct that
    reads them from the joined payloads, padding over the other nodes' bytes."""

    __slots__ = ("driver", "health", "keys", "unpack", "offset")

    def __init__(self, route, offset: int):
        self.driver, self.health = route.driver, route.health
        self.keys: tuple = ()
        self.offset = offset
        self.unpack = None


class BurstPlan:
    __slots__ = ("lengths", "nodes", "cobs", "count")

    def __init__(self, lengths: tuple[int, ...], nodes: tuple[NodeSlice, ...], cobs: frozenset[int]):
        self.lengths, self.nodes, self.cobs, self.count = lengths, nodes, cobs, len(lengths)


def build_plan(ids: tuple[int, ...], routes: dict) -> BurstPlan | None:
    """The plan for a burst of these COB-IDs in this order, or None where the per-frame path
    must decode it (module docstring)."""
    if len(set(ids)) != len(ids):
        return None
    formats: dict[int, list[str]] = {}       # id(health) -> the node's format pieces
    nodes: dict[int, NodeSlice] = {}
    ends: dict[int, int] = {}                # id(health) -> offset after the node's last frame so far
    lengths, offset = [], 0
    for cob in ids:
        route = routes.get(cob)
        if route is None or route.unpack is None or route.codec.struct.size > route.length:
            return None
        node = id(route.health)
        if node not in nodes:
            nodes[node], formats[node], ends[node] = NodeSlice(route, offset), [], offset
        elif nodes[node].driver is not route.driver:
            return None                      # two drivers behind one health: not a node's set
        gap = offset - ends[node]            # other nodes' frames in between
        pieces = formats[node]
        if gap:
            pieces.append(f"{gap}x")
        pieces.append(route.codec.struct.format.lstrip("<"))
        if route.length > route.codec.struct.size:
            pieces.append(f"{route.length - route.codec.struct.size}x")
        nodes[node].keys += route.keys
        offset += route.length
        ends[node] = offset
        lengths.append(route.length)
    for node, piece in nodes.items():
        piece.unpack = struct.Struct("<" + "".join(formats[node])).unpack_from
        if piece.keys == getattr(piece.driver, "tpdo_keys", None):
            # the node's whole layout in its order: the decode keeps the tuple (the driver's
            # `latest`, drivers/reported_values.py) while these are the driver's very keys
            piece.keys = piece.driver.tpdo_keys
    return BurstPlan(tuple(lengths), tuple(nodes.values()), frozenset(ids))
