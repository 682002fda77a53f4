"""The daemon's view of nodes answering late: in time, late answers, late heartbeats and
missing data give the levels and the advice the operator sees in status."""
from __future__ import annotations

import pytest

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


def answers_after_the_wait(timing: NodeTiming, cycles: int) -> None:
    """Each cycle's data missing at the read, then come later in its period (answered late)."""
    for k in range(cycles):
        timing.add(BUDGET, False, {}, last_answered_late=k > 0)
    timing.add(0.001, True, {}, last_answered_late=True)


def test_data_after_the_wait_in_more_than_5_percent_of_cycles_is_reported_with_advice():
    timing = NodeTiming(BUDGET)
    feed(timing, 224, 0.001)
    answers_after_the_wait(timing, 25)
    summary = timing.summary()
    assert summary.level == "late" and summary.late_cycles == 25 and summary.missing_cycles == 0
    assert "the data of 25 of the last 250 cycles came after the 8.0 ms wait" in summary.message
    assert "--rt-priority 50" in summary.message
    few = NodeTiming(BUDGET)
    feed(few, 240, 0.001)
    answers_after_the_wait(few, 10)
    assert few.summary().level == "ok"


def test_a_window_still_filling_judges_late_answers_as_a_share_of_the_whole_window():
    """One late cycle of the first three is no banner; as many late cycles as would make a full
    window late still are, however early they come."""
    timing = NodeTiming(BUDGET)
    feed(timing, 2, 0.001)
    answers_after_the_wait(timing, 1)
    assert timing.summary().level == "ok"
    early = NodeTiming(BUDGET)
    answers_after_the_wait(early, 13)
    summary = early.summary()
    assert summary.level == "late" and "13 of the last 14 cycles" in summary.message


def test_answers_inside_the_wait_are_on_time_however_late_in_it():
    """A simulator computing its physics answers 4-7 ms into the 8 ms wait on a loaded machine."""
    timing = NodeTiming(BUDGET)
    feed(timing, 250, 0.0079)
    assert timing.summary().level == "ok" and timing.summary().late_cycles == 0


def test_a_cycle_whose_data_came_after_the_wait_in_its_period_is_late_not_missing():
    timing = NodeTiming(BUDGET)
    feed(timing, 240, 0.001)
    timing.add(BUDGET, False, {})
    timing.add(0.001, True, {}, last_answered_late=True)
    summary = timing.summary()
    assert summary.missing_cycles == 0 and summary.late_cycles == 1 and summary.level == "ok"
    timing.add(BUDGET, False, {})
    timing.add(BUDGET, False, {})                  # the last one never answered: missing data
    assert timing.summary().missing_cycles == 2 and timing.summary().level == "starved"


def test_heartbeats_in_bursts_are_late():
    timing = NodeTiming(BUDGET)
    feed(timing, 250, 0.001, hb_every=0.2)
    summary = timing.summary()
    assert summary.level == "late" and summary.worst_node == "joint_1" and summary.heartbeat_gap >= 1.9


def test_in_lockstep_wall_clock_heartbeat_gaps_are_no_lateness_and_no_priority_is_advised():
    """A lockstep run through a bus line cut said "heartbeats of joint_6 10.3 periods apart;
    run `spacearm sim` ... with --rt-priority 50" of an in-process simulator on SYNC time."""
    timing = NodeTiming(0.0, lockstep=True)
    feed(timing, 250, 0.0, hb_every=0.2)
    assert timing.summary().level == "ok" and timing.summary().heartbeat_gap == 0.0
    feed(timing, 3, 0.0, complete=False)      # missing data is still judged: a cut line, a silent node
    summary = timing.summary()
    assert summary.level == "starved" and "3 of the last 250 cycles missed process data" in summary.message
    assert "rt-priority" not in summary.message


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


def _fifo_reports(now: float, worsts: list[float], cause: str = "core"):
    """One report a second, the last at `now` - 0.5; each with its worst wake."""
    from spacearm.base.canopen.peer_timing import TimingReport
    n = len(worsts)
    return [(now - 0.5 - (n - 1 - i), TimingReport(int(w > 0.005), w, 100, "SCHED_FIFO", 50, cause if w > 0.005 else ""))
            for i, w in enumerate(worsts)]


def test_one_late_wake_of_a_real_time_simulator_shows_no_banner_three_do_and_it_clears_slowly():
    timing = NodeTiming(BUDGET)
    feed(timing, 250, 0.001)
    one = timing.summary({"simulator": _fifo_reports(100.0, [0.001] * 9 + [0.06])}, 100.0)
    assert one.level == "ok" and one.peers["simulator"]["level"] == "ok"          # the host's odd hiccup
    three = timing.summary({"simulator": _fifo_reports(101.0, [0.03, 0.001, 0.04, 0.001, 0.05])}, 101.0)
    assert three.level == "late" and "waited for a core" in three.message
    # once late it stays so while a late report is in the window, and clears when none is
    assert timing.summary({"simulator": _fifo_reports(102.0, [0.001] * 4 + [0.03])}, 102.0).level == "late"
    assert timing.summary({"simulator": _fifo_reports(160.0, [0.001] * 5)}, 160.0).level == "ok"


def test_a_wake_that_could_stop_the_arm_is_late_at_once():
    timing = NodeTiming(BUDGET)
    feed(timing, 250, 0.001)
    summary = timing.summary({"simulator": _fifo_reports(100.0, [0.001] * 4 + [0.14], "gil")}, 100.0)
    assert summary.level == "late" and "waited for the GIL" in summary.message


@pytest.mark.parametrize("cause, says, advises", [
    ("core", "waited for a core", "higher real-time priority took its core"),
    ("gil", "waited for the GIL", "held the GIL"),
    ("stopped", "stopped (none of its threads ran)", "a debugger or SIGSTOP, or the host"),
])
def test_the_advice_names_the_measured_cause_and_never_rt_priority_to_a_fifo_process(cause, says, advises):
    timing = NodeTiming(BUDGET)
    feed(timing, 250, 0.001)
    summary = timing.summary({"simulator": _fifo_reports(100.0, [0.001, 0.03, 0.04, 0.05, 0.2], cause)}, 100.0)
    assert summary.level == "late" and says in summary.message and advises in summary.message
    assert "--rt-priority" not in summary.message


def test_a_peer_held_by_the_host_is_said_but_is_no_banner():
    """Its late wakes were the host's (CPU steal): the numbers and the cause are in its summary,
    the level stays ok (no setting of the stack helps); its own late wakes still count."""
    timing = NodeTiming(BUDGET)
    feed(timing, 250, 0.001)
    summary = timing.summary({"simulator": _fifo_reports(100.0, [0.001, 0.03, 0.04, 0.05, 0.2], "host")}, 100.0)
    peer = summary.peers["simulator"]
    assert summary.level == "ok" and peer["level"] == "ok" and peer["cause"] == "host"
    assert "on time but for the host" in peer["message"] and "the host did not run its vCPU" in peer["message"]
    mixed = _fifo_reports(100.0, [0.001, 0.03, 0.04, 0.05, 0.2], "host")[:-1] + _fifo_reports(100.0, [0.15], "core")
    assert NodeTiming(BUDGET).summary({"simulator": mixed}, 100.0).level == "late"


def test_data_missing_while_the_host_held_a_vcpu_is_said_not_starved():
    timing = NodeTiming(BUDGET)
    feed(timing, 240, 0.001)
    for _ in range(7):
        timing.add(BUDGET, False, {}, host_stalled=True)
    summary = timing.summary()
    assert summary.level == "ok" and summary.missing_cycles == 0 and summary.host_stalled_cycles == 7
    assert "the host held a vCPU in 7 of the last 247 cycles" in summary.message and summary.late_cycles == 0
    timing.add(BUDGET, False, {})                   # missing without a stall: the nodes'
    timing.add(BUDGET, False, {})
    assert timing.summary().level == "starved"


def test_a_heartbeat_gap_the_host_stall_made_is_no_banner():
    """The held vCPU held the simulator's heartbeats too: the gap that ends right after the
    stall is the host's; the same gap with no stall is the node's."""
    def run(stalled: bool) -> str:
        timing = NodeTiming(BUDGET)
        beats = [0.1 * k for k in range(30)] + [3.11]              # one beat 2.1 periods late
        t = 0.0
        for k in range(160):
            t += 0.02
            last = max(b for b in beats if b <= t + 1e-9)
            stall = stalled and 2.92 < t < 3.02
            timing.add(BUDGET if stall else 0.001, not stall, {"joint_1": (last, HB)}, host_stalled=stall)
        return timing.summary().level
    assert run(stalled=False) == "late" and run(stalled=True) == "ok"


def test_heartbeat_gaps_no_longer_than_a_host_held_wake_of_the_simulator_are_the_hosts():
    """The host held the simulator's timer (its report: 95 ms, cause host) while its SYNC answers
    came on time from another thread: three gaps 1.9 periods apart are the host's; with the
    same report naming a core, or gaps longer than the stall, they are the nodes'."""
    def summary(cause: str, late_by: float) -> str:
        timing = NodeTiming(BUDGET)
        beats = [0.0]
        for k in range(3):
            beats += [beats[-1] + 0.1 * j for j in (1, 2, 3)] + [beats[-1] + 0.4 + late_by]
        t = 0.0
        for _ in range(int((beats[-1] + 0.1) / 0.02)):
            t += 0.02
            timing.add(0.001, True, {"joint_1": (max(b for b in beats if b <= t + 1e-9), HB)})
        return timing.summary({"simulator": _fifo_reports(10.0, [0.001] * 4 + [0.095], cause)}, 10.0).level
    assert summary("host", 0.09) == "ok"
    assert summary("core", 0.09) == "late" and summary("host", 0.15) == "late"


def test_a_heartbeat_gap_while_this_process_itself_ran_late_is_no_banner():
    timing = NodeTiming(BUDGET)
    feed(timing, 100, 0.001)
    timing.add(0.001, True, {"joint_1": (1.0, HB)}, starved=True)     # skipped cycles just before
    timing.add(0.001, True, {"joint_1": (1.21, HB)})                   # a beat 2.1 periods after
    assert timing.summary().level == "ok"


def test_a_short_stall_seen_only_when_the_data_came_back_is_the_hosts():
    """A 60 ms stall: two missing cycles, then the first complete one shows the steal counted."""
    timing = NodeTiming(BUDGET)
    feed(timing, 240, 0.001)
    timing.add(BUDGET, False, {})
    timing.add(BUDGET, False, {})
    timing.add(0.001, True, {}, host_stalled=True)
    summary = timing.summary()
    assert summary.level == "ok" and summary.missing_cycles == 0 and summary.host_stalled_cycles == 2


def test_one_missed_cycle_is_said_two_in_a_row_or_three_in_the_window_are_a_banner():
    timing = NodeTiming(BUDGET)
    feed(timing, 240, 0.001)
    timing.add(BUDGET, False, {})
    feed(timing, 5, 0.001)
    summary = timing.summary()
    assert summary.level == "ok" and summary.missing_cycles == 1 and "1 of the last 246 cycles missed" in summary.message
    timing.add(BUDGET, False, {})
    feed(timing, 5, 0.001)
    assert timing.summary().level == "ok"
    timing.add(BUDGET, False, {})
    assert timing.summary().level == "starved"
    again = NodeTiming(BUDGET)
    feed(again, 240, 0.001)
    again.add(BUDGET, False, {})
    again.add(BUDGET, False, {})
    assert again.summary().level == "starved"


def test_the_first_cycles_of_a_gap_before_the_held_vcpu_showed_are_the_hosts_too():
    timing = NodeTiming(BUDGET)
    feed(timing, 240, 0.001)
    timing.add(BUDGET, False, {})
    timing.add(BUDGET, False, {})
    for _ in range(5):
        timing.add(BUDGET, False, {}, host_stalled=True)
    summary = timing.summary()
    assert summary.level == "ok" and summary.host_stalled_cycles == 7 and summary.missing_cycles == 0


def test_late_answers_beside_real_time_peers_on_time_do_not_advise_rt_priority():
    timing = NodeTiming(BUDGET)
    feed(timing, 224, 0.001)
    answers_after_the_wait(timing, 25)
    summary = timing.summary({"simulator": _fifo_reports(100.0, [0.001] * 5), "hub": _fifo_reports(100.0, [0.001] * 5)},
                             100.0)
    assert summary.level == "late" and "--rt-priority" not in summary.message
    assert "report on time at SCHED_FIFO 50" in summary.message


def test_one_heartbeat_gap_is_no_banner_repeated_or_long_ones_are():
    def beats(timing: NodeTiming, times: list[float]) -> None:
        for t in times:
            timing.add(0.001, True, {"joint_1": (t, HB)})

    timing = NodeTiming(BUDGET)
    regular = [0.1 * k for k in range(1, 100)]
    beats(timing, regular + [9.9 + 0.17] + [10.07 + 0.1 * k for k in range(1, 100)])   # one 1.7-period gap
    assert timing.summary().level == "ok"
    beats(timing, [20.0, 20.21])                               # 2.1 periods: near the 2.5-period stop
    assert timing.summary().level == "late"


def test_data_missing_while_a_bus_line_switch_bridges_it_is_the_lines_not_the_nodes():
    """A cut line: the cycles until the network is on the other line miss data, and the nodes'
    heartbeats of the cut line never come. Both are the switch's (said, no banner, no advice to
    run anything at a real-time priority); the same cycles with no switch are the nodes'."""
    def run(bridged: bool):
        timing = NodeTiming(BUDGET)
        feed(timing, 240, 0.001)
        timing.add(0.001, True, {"joint_2": (10.0, 0.1)})
        for _ in range(5):
            timing.add(BUDGET, False, {"joint_2": (10.0, 0.1)}, bridged=bridged)
        timing.add(0.001, True, {"joint_2": (10.7, 0.1)})     # heard again on the other line
        return timing.summary()
    switch, nodes = run(True), run(False)
    assert switch.level == "ok" and switch.missing_cycles == 0 and switch.heartbeat_gap < 2.0, switch
    assert "5 of the last 247 cycles bridged a bus line switch" in switch.message
    assert "--rt-priority" not in switch.message
    assert nodes.level == "starved" and nodes.missing_cycles == 5
