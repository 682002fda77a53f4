"""The daemon's view of nodes answering late: in time, late answers, late heartbeats and
missing data give the levels and the advice the operator sees in status."""
from __future__ import annotations

from spacearm.controller.daemon.node_timing import NodeTiming

BUDGET = 0.008
HB = 0.1


def feed(timing: NodeTiming, cycles: int, io_wait: float, complete: bool = True, hb_every: float = HB) -> None:
    t, last = 0.0, 0.0
    for _ in range(cycles):
        t += 0.02
        if t - last >= hb_every:
            last = t
        timing.add(io_wait, complete, {"joint_1": (last, HB)})


def test_nodes_answering_early_are_ok():
    timing = NodeTiming(BUDGET)
    feed(timing, 250, 0.001)
    summary = timing.summary()
    assert summary.level == "ok" and summary.late_cycles == 0 and summary.io_wait_p99 == 0.001


def test_answers_late_in_the_budget_are_reported_with_advice():
    timing = NodeTiming(BUDGET)
    feed(timing, 200, 0.001)
    feed(timing, 50, 0.006)
    summary = timing.summary()
    assert summary.level == "late" and summary.late_cycles == 50
    assert "--rt-priority 50" in summary.message


def test_heartbeats_in_bursts_are_late():
    timing = NodeTiming(BUDGET)
    feed(timing, 250, 0.001, hb_every=0.2)
    summary = timing.summary()
    assert summary.level == "late" and summary.worst_node == "joint_1" and summary.heartbeat_gap >= 1.9


def test_missing_data_is_starved():
    timing = NodeTiming(BUDGET)
    feed(timing, 240, 0.001)
    feed(timing, 3, BUDGET, complete=False)
    assert timing.summary().level == "starved" and timing.summary().missing_cycles == 3
