"""On the SYNC time base the simulator asks every node at every SYNC whether a consumed
heartbeat timed out; runner._consumers_quiet answers "nothing to do" without the call
(issue 35), and must only ever say so where SimNode.check_consumers would change nothing."""
from __future__ import annotations

from hypothesis import given, settings, strategies as st

from spacearm.base.canopen import od
from spacearm.firmware_sim import runner
from spacearm.firmware_sim.runner import Simulator

_SIMS: list[Simulator] = []


def _node():
    """A joint drive of the default bus config on the SYNC time base, not on a bus."""
    if not _SIMS:
        sim = Simulator("virtual:sync-time-timers-test", time_base="sync")
        sim.bus = object()        # not None: what the node sends goes nowhere
        sim._send_frame = sim._send_frames = lambda *frames: None
        _SIMS.append(sim)
    node = next(iter(_SIMS[0].nodes.values()))
    node.power_on()
    return node


def _write_entries(node, timeouts) -> None:
    """1016h: producer i + 1 consumed with timeouts[i] ms (0: the entry is off)."""
    for sub, ms in enumerate(timeouts, start=1):
        node.put(od.CONSUMER_HEARTBEAT, sub, sub << 16 | ms)
    node.put(od.CONSUMER_HEARTBEAT, 0, len(timeouts))


_ENTRIES = st.lists(st.one_of(st.just(0), st.integers(1, 3000)), min_size=1, max_size=3)


@settings(max_examples=500, deadline=None)
@given(st.dictionaries(st.integers(1, 3), st.floats(-5.0, 5.0, allow_nan=False), min_size=1, max_size=3),
       st.floats(-5.0, 10.0, allow_nan=False), _ENTRIES, st.sampled_from([True, True, True, False]),
       st.one_of(st.none(), st.none(), _ENTRIES))
def test_quiet_only_where_checking_the_consumers_changes_nothing(last, now, entries, cached, rewritten):
    """Entries cached (or not), then perhaps written again (the cache stale): whenever
    _consumers_quiet says quiet, check_consumers times nothing out and forgets no producer."""
    node = _node()
    _write_entries(node, entries)
    if cached:
        node.consumer_entries()
    if rewritten is not None:
        _write_entries(node, rewritten)
    node.consumer_last = dict(last)
    timed_out = []
    node.consumer_timed_out = lambda producer, at: timed_out.append(producer)
    try:
        quiet = runner._consumers_quiet(node, node.consumer_last, now)
        node.check_consumers(now)
    finally:
        del node.consumer_timed_out
    if quiet:
        assert node.consumer_last == last and not timed_out
