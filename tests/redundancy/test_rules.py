"""The two rules on their own, with a clock of the test's: the slave's (Lely's timer
arithmetic: first toggle (Ttoggle - 1) consumer times after the timeout, then every Ttoggle,
NO_MASTER at Ntoggle) and the master's (when it moves the network)."""
from __future__ import annotations

import pytest

from spacearm.base.canopen import od
from spacearm.base.canopen import redundancy_object as rdn
from spacearm.base.config.redundancy import RedundancySettings
from spacearm.drivers.line_redundancy import LINE_SWITCH, LINES_LOST, SWITCH_COMPLETE, LineRedundancyMaster
from spacearm.firmware_sim.line_selection import NodeLineRule


class FakeNode:
    def __init__(self, ttoggle=2, ntoggle=3, bdefault=0):
        self.store = {(rdn.REDUNDANCY, rdn.BDEFAULT): bdefault, (rdn.REDUNDANCY, rdn.TTOGGLE): ttoggle,
                      (rdn.REDUNDANCY, rdn.NTOGGLE): ntoggle, (rdn.REDUNDANCY, rdn.CTOGGLE): 0,
                      (od.CONSUMER_HEARTBEAT, 1): (127 << 16) | 100}

    def get(self, index, sub=0):
        return self.store[(index, sub)]

    def put(self, index, sub, value):
        self.store[(index, sub)] = value


def test_slave_rule_follows_lely_timer_arithmetic():
    node = FakeNode(ttoggle=2, ntoggle=3)
    rule = NodeLineRule(node)
    assert rule.master() == (127, 0.1) and rule.line == 0
    rule.master_missed(10.0, 0.1)                 # the consumer time already passed once
    assert not rule.due(10.099) and rule.due(10.1)
    assert rule.toggle(10.1, 0.1) == "switch" and rule.line == 1
    assert node.get(rdn.REDUNDANCY, rdn.CTOGGLE) == 1
    assert not rule.due(10.299) and rule.due(10.3)           # then every Ttoggle consumer times
    assert rule.toggle(10.3, 0.1) == "switch" and rule.line == 0
    assert rule.toggle(10.5, 0.1) == "no_master" and rule.line == 1
    assert node.get(rdn.REDUNDANCY, rdn.CTOGGLE) == 3
    assert node.get(rdn.REDUNDANCY, rdn.BDEFAULT) == 1       # stays where it gave up
    assert not rule.due(99.0)


def test_slave_finding_the_master_makes_that_line_the_default():
    node = FakeNode(ttoggle=1)
    rule = NodeLineRule(node)
    rule.master_missed(0.0, 0.1)
    assert rule.due(0.0)                          # Ttoggle 1: at once after the timeout
    rule.toggle(0.0, 0.1)
    assert rule.master_heard() and node.get(rdn.REDUNDANCY, rdn.BDEFAULT) == 1
    assert not rule.due(10.0)


def test_slave_ttoggle_zero_never_toggles():
    rule = NodeLineRule(FakeNode(ttoggle=0))
    rule.master_missed(0.0, 0.1)
    assert not rule.due(100.0)


class FakeBus:
    def __init__(self):
        self.active = 0
        self.rx_observers, self.tx_watch, self.standby_passes = [], {}, None


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def make_master(nodes=(1, 2, 3)):
    bus, clock = FakeBus(), Clock()
    settings = RedundancySettings(master_heartbeat_period=0.02, master_heartbeat_timeout=0.1)
    master = LineRedundancyMaster(bus, list(nodes), lambda cob: cob - 0x700 if 0x701 <= cob <= 0x77F else
                                  (cob - 0x180 if 0x181 <= cob <= 0x1FF else None),
                                  node_period=0.1, master_period=0.02, settings=settings, clock=clock, timer=False)
    return master, bus, clock


def hear(master, clock, line, nodes, t, state=od.NMT_STATE_OPERATIONAL):
    clock.t = t
    for n in nodes:
        master.on_rx(line, 0x700 + n, bytes([state]), t)


def test_master_switches_after_two_unanswered_syncs_and_completes():
    master, bus, clock = make_master()
    hear(master, clock, 0, (1, 2, 3), 0.0)
    clock.t = 0.01
    master.on_tx(0, 0x080)
    assert bus.active == 0 and master.bridging()
    clock.t = 0.03
    master.on_tx(0, 0x080)
    assert bus.active == 0          # two SYNCs, but not yet two master heartbeat periods of silence
    clock.t = 0.05
    master.on_tx(0, 0x080)
    assert bus.active == 1 and [e.code for e in master.events] == [LINE_SWITCH]
    hear(master, clock, 1, (1, 2), 0.1)
    assert master.bridging()
    hear(master, clock, 1, (3,), 0.11)
    assert master.events[-1].code == SWITCH_COMPLETE
    assert master.events[-1].duration == pytest.approx(0.11)
    assert not master.bridging()


def test_master_follows_nodes_heard_on_the_other_line():
    master, bus, clock = make_master()
    hear(master, clock, 0, (1, 2, 3), 0.0)
    hear(master, clock, 1, (1,), 0.05)
    assert bus.active == 0                        # one of three: that node's own trouble
    hear(master, clock, 1, (2,), 0.06)
    assert bus.active == 1


def test_master_does_not_chase_back_to_a_line_it_left_for_silence():
    master, bus, clock = make_master()
    hear(master, clock, 0, (1, 2, 3), 0.0)
    for t in (0.01, 0.05):
        clock.t = t
        master.on_tx(0, 0x080)
    assert bus.active == 1
    master.check(0.2)                             # B silent too: A was left for silence
    assert bus.active == 1


def test_master_reports_both_lines_lost_once_then_searches_slowly():
    master, bus, clock = make_master()
    hear(master, clock, 0, (1, 2, 3), 0.0)
    for t in (0.01, 0.05):
        clock.t = t
        master.on_tx(0, 0x080)
    for t in (0.1, 0.2, 0.3, 0.4):
        clock.t = t
        master.check(t)
    lost = [e for e in master.events if e.code == LINES_LOST]
    assert len(lost) == 1 and lost[0].time <= 0.3
    assert not master.bridging()
    switches = sum(e.code == LINE_SWITCH for e in master.events)
    clock.t = 1.5
    master.check(1.5)
    assert sum(e.code == LINE_SWITCH for e in master.events) == switches + 1
    hear(master, clock, bus.active, (1, 2, 3), 1.6)
    assert not master.lost


def test_settings_refuse_a_consumer_time_below_two_heartbeats():
    with pytest.raises(ValueError, match="two master heartbeat periods"):
        RedundancySettings(master_heartbeat_period=0.05, master_heartbeat_timeout=0.06)


class JudgedEveryTime(LineRedundancyMaster):
    """The master's rule as it was before its quiet time: every SYNC and every pass judged in full."""

    def _quiet_at(self, now):
        return False


def _random_history(seed: int, steps: int = 400):
    """What a master sees of three nodes, at random: heartbeats (some not OPERATIONAL), process
    data noted on either line, SYNCs, timer passes, nodes moving to the other line, silences."""
    import random

    rng = random.Random(seed)
    t, history, home = 0.0, [], {1: 0, 2: 0, 3: 0}
    for _ in range(steps):
        t += rng.choice((0.0, 0.001, 0.005, 0.01, 0.01, 0.02, 0.02, 0.05, 0.2))
        r = rng.random()
        if r < 0.03:
            node = rng.choice((1, 2, 3))
            home[node] ^= 1                       # this node now talks on the other line
        elif r < 0.10:
            node = rng.choice((1, 2, 3))
            state = od.NMT_STATE_OPERATIONAL if rng.random() < 0.9 else od.NMT_STATE_PRE_OPERATIONAL
            history.append(("hb", t, home[node], node, state))
        elif r < 0.45 and rng.random() < 0.9:     # (sometimes nobody answers for a while)
            nodes = [n for n in (1, 2, 3) if rng.random() < 0.9]
            history.append(("pdo", t, nodes, dict(home)))
        elif r < 0.7:
            history.append(("sync", t))
        else:
            history.append(("pass", t))
    return history


def _replay(master, bus, clock, history):
    seen = []
    for step in history:
        clock.t = step[1]
        if step[0] == "hb":
            master.on_rx(step[2], 0x700 + step[3], bytes([step[4]]), step[1])
        elif step[0] == "pdo":
            for node in step[2]:
                line, cob = step[3][node], 0x180 + node
                if line == bus.active:
                    master._seen[line].add(cob)      # as the pair notes the active line's frames
                else:
                    master.on_rx(line, cob, b"\0" * 8, step[1])
        elif step[0] == "sync":
            master.on_tx(bus.active, 0x080)
        else:
            master.check(step[1])
        seen.append((bus.active, master.lost, master.bridging(step[1]), len(master.events)))
    return seen, [(e.time, e.code, e.line, e.duration) for e in master.events]


@pytest.mark.parametrize("seed", range(40))
def test_master_quiet_time_skips_only_judgements_that_say_nothing(seed):
    """The usual SYNC and timer pass skip _decide while the rule is quiet (issue 34: its cost);
    over random histories the rule must switch, complete, lose and search exactly as when it
    judges every time."""
    fast, fast_bus, fast_clock = make_master()
    full, full_bus, full_clock = make_master()
    full.__class__ = JudgedEveryTime
    history = _random_history(seed)
    assert _replay(fast, fast_bus, fast_clock, history) == _replay(full, full_bus, full_clock, history)


def test_master_quiet_time_is_taken_on_a_calm_network():
    """A calm network (every node answering every SYNC on the active line) is not judged in full
    at every SYNC and pass: between two answers only the quiet time is looked at."""
    master, bus, clock = make_master()
    hear(master, clock, 0, (1, 2, 3), 0.0)
    judged = []
    decide = master._decide
    master._decide = lambda now: judged.append(now) or decide(now)
    for k in range(1, 101):
        clock.t = k * 0.02
        master.on_tx(0, 0x080)
        master._seen[0].update({0x181, 0x182, 0x183})
        master.check(clock.t + 0.005)
        master.check(clock.t + 0.015)
    assert bus.active == 0 and not master.events
    assert len(judged) <= 100 // 7 + 1       # one in the silence time (0.15 s) at most, not 300
