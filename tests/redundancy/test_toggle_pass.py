"""Nodes whose master heartbeat timed out together toggle in one hold of the simulator's SYNC
lock (firmware_sim/line_selection.py timer_pass). Each toggle used to take the lock on its own,
so a SYNC could come between two of them; a SYNC preempted there held the remaining nodes on
the old line for as long (a CI run: ft_sensor, the last node, toggled 200 ms after the others,
with no starvation counted, and the master declared it lost). Here a SYNC is handled whenever
the pass looks a node's master up, which is outside the lock, as often as the pass allows."""
from __future__ import annotations

import time
import uuid
from collections import defaultdict

from spacearm.base.canopen import od
from spacearm.base.canopen import redundancy_object as rdn
from spacearm.base.config.bus import load_bus_config
from spacearm.base.transport import open_bus
from spacearm.firmware_sim.runner import Simulator

MASTER = 127


def test_nodes_due_in_one_pass_toggle_with_no_sync_between(monkeypatch):
    tag = uuid.uuid4().hex[:8]
    lines = (f"virtual:pass-a-{tag}", f"virtual:pass-b-{tag}")
    sim = Simulator("+".join(lines), load_bus_config()).start()
    line_a = open_bus(lines[0])
    selection = sim.line_selection
    passes = [0]
    toggles: dict[int, list[tuple[str, int]]] = defaultdict(list)    # pass -> (node, SYNCs handled then)
    try:
        for node_id, rule in selection.rules.items():
            node = sim.nodes[node_id]
            node.put(od.CONSUMER_HEARTBEAT, rdn.MASTER_CONSUMER_SUB, (MASTER << 16) | 60)

            def master(rule=rule, looked_up=rule.master):
                if not sim._sync_lock.locked():       # (the consumer check asks under the lock)
                    line_a.send_frame(od.SYNC_COB_ID_DEFAULT, b"")
                return looked_up()

            def toggle(now, consumer_time, name=node.name, toggled=rule.toggle):
                toggles[passes[0]].append((name, sim.stats.syncs))
                return toggled(now, consumer_time)
            monkeypatch.setattr(rule, "master", master)
            monkeypatch.setattr(rule, "toggle", toggle)
        timer_pass = selection.timer_pass

        def counted_pass(locked: bool = False) -> bool:
            passes[0] += 1
            return timer_pass(locked)
        monkeypatch.setattr(selection, "timer_pass", counted_pass)
        line_a.send_frame(od.NMT_COB_ID, bytes([od.NMT_START, 0]))
        end = time.monotonic() + 0.2
        while time.monotonic() < end:       # the master beats on line A, then falls silent
            line_a.send_frame(od.HEARTBEAT_BASE + MASTER, bytes([od.NMT_STATE_OPERATIONAL]))
            time.sleep(0.02)
        end = time.monotonic() + 2.0
        while len({name for pass_toggles in toggles.values() for name, _ in pass_toggles}) < len(selection.rules):
            assert time.monotonic() < end, f"not every node toggled: {dict(toggles)}"
            time.sleep(0.01)
    finally:
        line_a.shutdown()
        sim.stop()
    together = [pass_toggles for pass_toggles in toggles.values() if len(pass_toggles) > 1]
    assert together, f"no two nodes toggled in one pass: {dict(toggles)}"
    for pass_toggles in together:
        assert len({syncs for _, syncs in pass_toggles}) == 1, f"a SYNC came between toggles: {pass_toggles}"
