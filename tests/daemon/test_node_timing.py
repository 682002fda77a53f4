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


def _reports(now: float, late: int, worst: float, count: int = 5, age: float = 0.5):
    from spacearm.base.canopen.peer_timing import TimingReport
    return [(now - age - (count - 1 - i), TimingReport(late if i == count - 1 else 0, worst if i == count - 1 else 0.001,
                                                      100, "normal", 0)) for i in range(count)]


def test_a_late_simulator_is_named_beside_the_daemons_own_view():
    timing = NodeTiming(BUDGET)
    feed(timing, 250, 0.001)
    summary = timing.summary({"simulator": _reports(100.0, 3, 0.301), "hub": _reports(100.0, 0, 0.0004)}, 100.0)
    assert summary.level == "late"
    assert summary.message.startswith("simulator late: 3 late of 500 cycles, max 301.0 ms")
    assert "run `spacearm sim` with --rt-priority 50" in summary.message
    assert "hub late" not in summary.message and "`spacearm hub`" not in summary.message   # the hub was on time
    assert summary.peers["hub"]["level"] == "ok" and summary.peers["simulator"]["max_lateness"] > 0.3


def test_a_starved_daemon_view_names_the_simulator_first():
    timing = NodeTiming(BUDGET)
    feed(timing, 240, 0.001)
    feed(timing, 10, BUDGET, complete=False)
    summary = timing.summary({"simulator": _reports(100.0, 1, 0.3)}, 100.0)
    assert summary.level == "starved"
    assert summary.message.startswith("simulator late") and "the daemon sees: 10 of the last" in summary.message


def test_a_peer_that_stops_reporting_is_silent_and_one_that_never_reported_is_not_shown():
    timing = NodeTiming(BUDGET)
    feed(timing, 250, 0.001)
    summary = timing.summary({"simulator": _reports(100.0, 0, 0.001, age=5.0), "hub": []}, 100.0)
    assert summary.peers["simulator"]["level"] == "silent" and "hub" not in summary.peers
    assert "simulator silent" in summary.message
