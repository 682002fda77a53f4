"""Bus redundancy end to end on virtual lines: the simulated nodes' slave rule
(firmware_sim/line_selection.py) and the master's rule (drivers/line_redundancy.py),
judged by what the nodes and the lines did, not by the master's own view alone."""
from __future__ import annotations

from spacearm.base.canopen import redundancy_object as rdn
from spacearm.base.transport.line_faults import line_fault
from spacearm.drivers.line_redundancy import LINE_SWITCH, LINES_LOST, SWITCH_COMPLETE

FAULT_KINDS = {"heartbeat_lost", "bootup", "emcy", "fault_reset_failed"}


def switch_time(pair, cut_at: float, line: int) -> float:
    """s from the cut until the master and every node are on `line` (from their own events)."""
    node_times = [e.time for e in pair.selection.events if e.kind == "switch" and e.line == line and e.time >= cut_at]
    master_times = [e.time for e in pair.master.events if e.code == LINE_SWITCH and e.line == line
                    and e.time >= cut_at]
    assert master_times, "the master did not switch"
    assert set(pair.node_lines().values()) == {line}, pair.node_lines()
    return max(node_times + master_times) - cut_at


def no_faults(pair, since: float) -> bool:
    """No fault event since `since`, unless the processes were starved beyond the heartbeat
    loss margin meanwhile (then the silence was this machine's, not the bus's; printed)."""
    faults = [e for e in pair.events if e.kind in FAULT_KINDS and e.time >= since]
    starved = pair.starved() - pair.starved_at_cut
    margin = (3.0 - pair.net.config.bus.heartbeat_loss_factor) * 0.1
    if faults:
        print(f"{len(faults)} fault events with {1e3 * starved:.0f} ms starved: {faults[0]}")
        print("node toggles since: " + ", ".join(f"{e.node} {1e3 * (e.time - since):.0f} ms"
                                               for e in pair.selection.events if e.time >= since))
    return not faults or starved > margin


def test_active_line_cut_then_the_other_fails_later(pair):
    pair.run(0.3)
    start = pair.master.active      # nominal, unless a starved heartbeat already moved the network
    assert set(pair.node_lines().values()) == {start}

    cut_at = pair.cut(start)
    pair.run(0.6)
    assert pair.within_heartbeat_periods(switch_time(pair, cut_at, start ^ 1))
    assert pair.master.active == start ^ 1
    assert any(e.code == SWITCH_COMPLETE for e in pair.master.events)
    # every node counted its toggle in its own object, as the master reads it back
    for node in pair.sim.nodes.values():
        if node.node_id in pair.selection.rules:
            assert pair.net.sdo_read(node.name, rdn.REDUNDANCY, rdn.CTOGGLE) >= 1
    state = pair.net.cycle(timeout=0.1)
    assert state.complete and all(j.enabled for j in state.joints)

    assert no_faults(pair, cut_at)
    pair.restore(start)
    cut_b = pair.cut(start ^ 1)
    pair.run(0.6)
    assert pair.within_heartbeat_periods(switch_time(pair, cut_b, start))
    assert no_faults(pair, cut_b)
    state = pair.net.cycle(timeout=0.1)
    assert state.complete and all(j.enabled for j in state.joints)


def test_both_lines_lost_is_one_coded_event_and_the_nodes_give_up(pair):
    pair.run(0.2)
    cut_at = pair.cut(0)
    pair.cut(1)
    pair.run(0.5)
    rdn_nodes = [pair.sim.nodes[i].name for i in pair.selection.rules]
    for _ in range(40):     # the nodes search Ntoggle x Ttoggle consumer times, then give up
        if {e.node for e in pair.selection.events if e.kind == "no_master"} >= set(rdn_nodes):
            break
        pair.run(0.1)
    lost = [e for e in pair.master.events if e.code == LINES_LOST]
    assert len(lost) == 1
    assert pair.within_heartbeat_periods(lost[0].time - cut_at)
    assert any(e.kind == LINES_LOST for e in pair.events)
    # each node searched Ntoggle times, then stayed and took its heartbeat-loss reaction
    ntoggle = pair.net.config.bus.redundancy.max_toggles
    for name in rdn_nodes:
        assert [e.kind for e in pair.selection.events if e.node == name].count("switch") == ntoggle
        assert any(e.kind == "no_master" for e in pair.selection.events if e.node == name)


def test_babbling_node_on_the_active_line_moves_the_network(pair):
    pair.run(0.2)
    start = pair.master.active
    cut_at = pair.cut(start, "babble")
    pair.run(0.6)
    assert pair.within_heartbeat_periods(switch_time(pair, cut_at, start ^ 1))
    # the flood was on the line (whether any of it reached the master's handlers depends on when
    # the switch came: once the line is standby only heartbeats and EMCYs pass), and nothing faulted
    assert line_fault(pair.lines[start]).flood_frames > 0
    assert pair.net.stats.malformed == 0 and pair.net.stats.callback_errors == 0
    assert no_faults(pair, cut_at)


def test_intermittent_line_moves_the_network_and_nothing_faults(pair):
    pair.run(0.2)
    start = pair.master.active
    cut_at = pair.cut(start, "intermittent", loss=0.7, seed=3)
    pair.run(1.0)
    assert pair.master.active == start ^ 1 and set(pair.node_lines().values()) == {start ^ 1}
    assert no_faults(pair, cut_at)


def test_a_sync_the_cut_line_kept_off_is_not_waited_for_and_is_no_silence(pair):
    """A SYNC a line fault kept off reached no node (the simulator counts none), so nothing can
    answer it: the TPDO wait ends at once, counts no timeout and observes no silence (a lockstep
    cycle on a cut line used to wait out its whole timeout, 7.5 s in the vcan VM). Once the line
    carries the SYNC again, the nodes answer it and the wait ends complete."""
    pair.run(0.2)
    line = pair.master.active
    syncs, timeouts = pair.sim.stats.syncs, pair.net.stats.tpdo_timeouts
    pair.cut(line)
    pair.net.send_sync()
    assert pair.net.wait_all_tpdos(timeout=5.0) is False
    assert pair.sim.stats.syncs == syncs, "the kept-off SYNC reached the simulator"
    assert pair.net.stats.syncs_kept_off == 1
    assert pair.net.stats.tpdo_timeouts == timeouts and pair.net._lockstep_wait_expired == 0.0
    pair.restore(line)
    pair.net.send_sync()
    assert pair.net.wait_all_tpdos(timeout=5.0) is True
    assert pair.sim.stats.syncs == syncs + 1 and pair.net.stats.syncs_kept_off == 1
