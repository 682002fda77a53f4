"""The master's side of bus redundancy on a redundant pair of lines (ECSS-E-ST-50-15C; the
objects and the slave's rule, with their sources, are in base/canopen/redundancy_object.py
and firmware_sim/line_selection.py).

The controller has parallel bus access: it hears both lines (base/transport/redundant.py)
and sends everything (its heartbeat, SYNC, RPDOs, SDO, NMT) on the active one. The nodes
follow its heartbeat, so moving the active line moves the network. The rule it moves by
(Lely leaves this decision to the application; ours, from the nodes' traffic per line):

* the active line is silent (judged only while nodes are OPERATIONAL: in bring-up a node
  talks only when asked): two SYNCs in a row went out on it and no node frame came back for
  two master heartbeat periods (a dead line shows within two or three cycles), or no node
  frame for 1.5 of the slowest node's heartbeat periods (an idle network) -> switch;
* most nodes are heard on the other line more recently than on the active one (they
  toggled there: the active line does not reach them) -> switch;
* after a switch it waits `hold_off` (the nodes' toggle time plus two master heartbeat
  periods) before it goes back for nodes heard on the old line, so the nodes have time to
  follow; a line it left for silence is not chosen again for silence of the other within
  `lost_after` (only when nodes are heard there, or in the search below): flipping back
  while starved nodes are still on their way would chase them from line to line;
* no node frame on either line for `lost_after` (that time and three more master heartbeat
  periods) -> both lines lost (the daemon's protective stop `bus_lines_lost`); it keeps
  alternating lines, once a second, to find the network again.

While a switch is under way (the active line silent, or switched less than `lost_after`
ago and not every node back) `bridging()` is True: the daemon does not count that cycle's
missing process data as node loss; the window ends at `lost_after`, so a node that does not
come back is still lost within the usual bounds.

What it reads per frame (a second line must cost a cycle almost nothing, issue 34): a node
frame on the active line is one set insertion (`_seen`), folded into the rule at the next
SYNC and timer pass (`_absorb`); heartbeats and every frame of the standby line are judged as
they come. What it judges per SYNC and pass: nothing while it is quiet (`_calm`: every node
heard on the active line, none on the other since, no switch under way, fewer than two SYNCs
unanswered: no answer but "stay" is possible before the active line's silence or loss time).
In real time each of those passes runs cold after its sleep, where a few lines of Python cost
ten times their price in a lockstep loop. Of the standby line only heartbeats (boot-ups) and
EMCYs reach the network's handlers (`standby_passes`): the nodes' life and their error
reports, never process data or SDO answers of a line the master does not drive.

Every switch is a LineEvent with a code: `line_switch`, `line_switch_complete` (every node
heard on the new line; with the time from the old line's last frame), `bus_lines_lost`.
"""
from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from spacearm.base.canopen import od
from spacearm.base.config.bus import BusConfig
from spacearm.base.config.redundancy import RedundancySettings
from spacearm.base.transport.redundant import LINE_NAMES

logger = logging.getLogger(__name__)

LINE_SWITCH = "line_switch"
SWITCH_COMPLETE = "line_switch_complete"
LINES_LOST = "bus_lines_lost"

SYNCS_UNANSWERED = 2        # SYNCs with no node frame back before the active line counts as silent
IDLE_SILENCE_PERIODS = 1.5  # node heartbeat periods of silence that make an idle line silent
SEARCH_PERIOD = 1.0         # s between switches while both lines are lost
TICK = 0.010                # s: the rule's timer (health.py's MONITOR_PERIOD; the silences it judges are >= 40 ms)
STARVED_SLACK = 0.020       # s: a timer pass this late was starved (health.py's slack)
CHECKED_RECENTLY = 0.001    # s: bridging() takes a check() this recent as its own


@dataclass(frozen=True)
class LineEvent:
    time: float             # monotonic
    code: str               # LINE_SWITCH | SWITCH_COMPLETE | LINES_LOST
    line: int               # the active line after the event
    message: str
    duration: float | None = None   # SWITCH_COMPLETE: s from the old line's last node frame


def standby_passes(can_id: int) -> bool:
    """The frames of the standby line that reach the master's handlers: heartbeats (and
    boot-ups) and EMCYs."""
    function = can_id & 0x780
    return (function == od.HEARTBEAT_BASE or function == od.EMCY_BASE) and can_id & 0x7F != 0


def settings_of(config: BusConfig) -> RedundancySettings:
    return getattr(config.bus, "redundancy", None) or RedundancySettings()


def bus_config_for(bus_spec: str, config: BusConfig) -> BusConfig:
    """On a redundant pair the controller's heartbeat and the nodes' consumer time for it are
    the [bus.redundancy] ones (they set how fast the nodes follow); one line: unchanged."""
    from spacearm.base.transport.redundant import PAIR_SEPARATOR

    if PAIR_SEPARATOR not in bus_spec:
        return config
    r = settings_of(config)
    bus = config.bus.model_copy(update={"master_heartbeat_period": r.master_heartbeat_period,
                                        "master_heartbeat_timeout": r.master_heartbeat_timeout})
    return config.model_copy(update={"bus": bus})


def redundancy_writes(config: BusConfig) -> list[tuple[int, int, int]]:
    """What bring-up writes to a node's redundancy object (where its EDS has it)."""
    from spacearm.base.canopen import redundancy_object as rdn

    r = settings_of(config)
    return [(rdn.REDUNDANCY, rdn.BDEFAULT, r.default_line_index), (rdn.REDUNDANCY, rdn.TTOGGLE, r.toggle_time),
            (rdn.REDUNDANCY, rdn.NTOGGLE, r.max_toggles), (rdn.REDUNDANCY, rdn.CTOGGLE, 0)]


class LineRedundancyMaster:
    """The master's rule on one RedundantBus. `node_of(can_id)` names the node that sends a
    COB-ID (None: not a node's frame). Times are monotonic s; `clock` is for tests."""

    def __init__(self, bus, node_ids: list[int], node_of: Callable[[int], int | None], *,
                 node_period: float, master_period: float, settings: RedundancySettings,
                 on_event: Callable[[LineEvent], None] | None = None, clock=time.monotonic,
                 timer: bool = True):
        self.bus = bus
        self.node_ids = list(node_ids)
        self.node_of = node_of
        self.on_event = on_event
        self.clock = clock
        self.silence = IDLE_SILENCE_PERIODS * node_period
        self.master_period = master_period
        self.hold_off = settings.switch_time() + 2 * master_period
        self.lost_after = self.hold_off + 3 * master_period
        self.heard: tuple[dict[int, float], dict[int, float]] = ({}, {})
        self.line_last: list[float | None] = [None, None]
        self.unanswered = [0, 0]
        self.operational: set[int] = set()
        self.switched_at = float("-inf")
        self.failed_at: float | None = None      # the old line's last node frame, for the switch under way
        self.pending: set[int] = set()           # nodes not yet heard on the new line
        self.lost = False
        self.left_silent_at = [float("-inf")] * 2   # when the line was left for silence (no node heard since)
        self._checked_at = float("-inf")
        self.switches = 0
        self.bridged_cycles = 0
        self.events: list[LineEvent] = []
        self._seen: tuple[set[int], set[int]] = (set(), set())   # COB-IDs on each line since the last _absorb
        # (line, time): before that time the rule can decide nothing on that line while no frame
        # of the other line, no switch and no second unanswered SYNC comes (_calm); the usual
        # timer pass and SYNC then skip _decide and _lost_check (issue 34: their cost, every 10 ms)
        self._quiet: tuple[int, float] = (0, float("-inf"))
        self._lock = threading.Lock()
        self._stop = threading.Event()
        bus.rx_observers.append(self.on_rx)
        bus.tx_watch.setdefault(od.SYNC_COB_ID_DEFAULT, []).append(self.on_tx)
        bus.standby_passes = standby_passes
        bus.rx_note = self._seen          # the in-process pair notes active-line frames without a call
        self._thread = None
        if timer:
            self._thread = threading.Thread(target=self._run, name="arm-line-redundancy", daemon=True)
            self._thread.start()

    @property
    def active(self) -> int:
        return self.bus.active

    # ------------------------------------------------------------------ what the lines show
    def on_rx(self, line: int, can_id: int, data: bytes, timestamp: float) -> None:
        if line == self.bus.active and can_id & 0x780 != od.HEARTBEAT_BASE:
            self._seen[line].add(can_id)        # the hot path (every TPDO): judged at the next SYNC or pass
            return
        node = self.node_of(can_id)
        if node is None:
            return
        now = self.clock()
        with self._lock:
            # a heartbeat of the active line needs no absorbing first: the next SYNC or pass does it
            events = self._absorb(now) if line != self.bus.active else []
            if can_id == od.HEARTBEAT_BASE + node and len(data) == 1:
                if data[0] & 0x7F == od.NMT_STATE_OPERATIONAL:
                    self.operational.add(node)
                else:
                    self.operational.discard(node)
            events += self._heard(line, (node,), now)
        if events:
            self._emit(events)

    def _heard(self, line: int, nodes, now: float) -> list[LineEvent]:
        """Under the lock: frames of `nodes` came on `line` (as of now)."""
        heard = self.heard[line]
        for node in nodes:
            heard[node] = now
        self.line_last[line] = now
        self.unanswered[line] = 0
        self.left_silent_at[line] = float("-inf")
        self.lost = False
        if line != self.bus.active:
            self._quiet = (line ^ 1, float("-inf"))     # the other line's news: judged in full from now on
            return self._decide(now)
        if self.pending and not self.pending.isdisjoint(nodes):
            self.pending.difference_update(nodes)
            if not self.pending:
                return [self._complete(now)]
        return []

    def _absorb(self, now: float) -> list[LineEvent]:
        """Under the lock: the node frames the hot path only noted, as heard now (once per
        node and line, however many PDOs it sent)."""
        events = []
        for line in (0, 1):
            seen = self._seen[line]
            if not seen:
                continue
            ids = set(seen)
            seen.difference_update(ids)    # not clear(): a frame noted meanwhile stays for the next pass
            nodes = set(map(self.node_of, ids))
            nodes.discard(None)
            if nodes:
                events += self._heard(line, nodes, now)
        return events

    def on_tx(self, line: int, can_id: int) -> None:
        if can_id != od.SYNC_COB_ID_DEFAULT or line != self.bus.active:
            return
        with self._lock:
            now = self.clock()
            events = self._absorb(now)
            if self.operational:
                self.unanswered[line] += 1
                # the usual cycle's SYNC is not judged (issue 34: its cost): every node heard on
                # this line as of now, fewer SYNCs than SYNCS_UNANSWERED unanswered, no frame of
                # the other line newer, the network not lost: _decide could only say "stay" (no
                # silence, no node ahead on the other line, no search)
                # (in real time the timer pass took this line's frames already: the quiet time says it)
                heard, other_last = self.heard[line], self.line_last[line ^ 1]
                if not self._quiet_at(now) and not (
                        self.unanswered[line] < SYNCS_UNANSWERED and not self.lost
                        and len(heard) == len(self.node_ids) and min(heard.values()) >= now
                        and (other_last is None or other_last <= now)):
                    events += self._decide(now)
                    if self.clock is not time.monotonic:
                        events += self._lost_check(now)     # lockstep: judged per SYNC only
                    self._quiet = self._calm()
        if events:
            self._emit(events)

    # ------------------------------------------------------------------ the rule
    def _decide(self, now: float) -> list[LineEvent]:
        """Under the lock: switch if the rule says so; returns the events to emit."""
        active, other = self.bus.active, self.bus.active ^ 1
        last = self.line_last[active]
        if last is None and self.line_last[other] is None:
            return []                               # nothing heard yet: not armed
        moved = []
        other_last, heard_active = self.line_last[other], self.heard[active]
        # the nodes heard on the other line later than on this one: only looked for when the other
        # line's last frame is newer than the switch and than some node's last frame here
        if other_last is not None and other_last > self.switched_at and (
                len(heard_active) < len(self.node_ids) or other_last > min(heard_active.values())):
            moved = [n for n in self.node_ids
                     if self.heard[other].get(n, float("-inf")) > max(heard_active.get(n, float("-inf")),
                                                                      self.switched_at)]
        # right after a switch of its own the master waits for the nodes: frames they still send
        # on the old line until they toggle are not a reason to go back
        if 2 * len(moved) > len(self.node_ids) and now - self.switched_at >= self.hold_off:
            return [self._switch(now, f"{len(moved)} of {len(self.node_ids)} nodes are heard on line "
                                      f"{LINE_NAMES[other]} only")]
        if self.lost:
            return [self._switch(now, "searching for the nodes")] if now - self.switched_at >= SEARCH_PERIOD else []
        # silence counts only while nodes are OPERATIONAL (as the nodes' own rule): in bring-up a
        # node talks only when asked, and a slow SDO answer is no dead line
        if not self.operational:
            return []
        if now - self.switched_at < self.hold_off or now - self.left_silent_at[other] < self.lost_after:
            return []
        # two master heartbeat periods of silence too: a loaded machine's late answers are no dead line
        if self.unanswered[active] >= SYNCS_UNANSWERED and now - (last if last is not None else self.switched_at) \
                >= SYNCS_UNANSWERED * self.master_period:
            self.left_silent_at[active] = now
            return [self._switch(now, f"{self.unanswered[active]} SYNCs on line {LINE_NAMES[active]} "
                                      "brought no node frame")]
        if now - (last if last is not None else self.switched_at) > self.silence:
            self.left_silent_at[active] = now
            return [self._switch(now, f"no node frame on line {LINE_NAMES[active]} for "
                                      f"{now - (last if last is not None else self.switched_at):.3f} s")]
        return []

    def _switch(self, now: float, why: str) -> LineEvent:
        old = self.bus.active
        self.bus.active = old ^ 1
        self._quiet = (old, float("-inf"))
        self.switches += 1
        if self.failed_at is None or not self.pending:
            self.failed_at = self.line_last[old] if self.line_last[old] is not None else now
        self.switched_at = now
        self.unanswered[old ^ 1] = 0
        self.pending = set(self.node_ids)
        message = f"bus line {LINE_NAMES[old]} -> {LINE_NAMES[old ^ 1]}: {why}"
        logger.warning(message)
        return LineEvent(now, LINE_SWITCH, old ^ 1, message)

    def _complete(self, now: float) -> LineEvent:
        duration = now - self.failed_at if self.failed_at is not None else None
        self.failed_at = None
        return LineEvent(now, SWITCH_COMPLETE, self.bus.active,
                         f"every node on line {LINE_NAMES[self.bus.active]}"
                         + (f", {1e3 * duration:.0f} ms after the old line's last frame" if duration is not None
                            else ""), duration)

    def check(self, now: float | None = None) -> None:
        """The rule's judgement at `now` (the timer's pass; tests call it with their own clock)."""
        now = self.clock() if now is None else now
        with self._lock:
            self._checked_at = now
            events = self._absorb(now)
            if not self._quiet_at(now):       # the usual pass: nothing to judge before the quiet time
                events += self._decide(now)
                events += self._lost_check(now)
                self._quiet = self._calm()
        if events:
            self._emit(events)

    def _calm(self) -> tuple[int, float]:
        """Under the lock, after a judgement: (active line, until when _decide and _lost_check
        must answer nothing) as long as no frame of the other line comes (_heard drops it), no
        switch happens and no second SYNC goes unanswered (_quiet_at checks those). Calm: not lost,
        no switch under way, every node heard on the active line and none on the other line since
        (no node can have moved); the first thing that can happen then is silence of the active
        line (`silence` after its last frame) or the loss of both (`lost_after` after it). Frames
        of the active line only move those times later."""
        active = self.bus.active
        heard, last, other_last = self.heard[active], self.line_last[active], self.line_last[active ^ 1]
        if self.lost or self.pending or last is None or not heard or len(heard) < len(self.node_ids) or (
                other_last is not None and other_last > min(heard.values())):
            return (active, float("-inf"))
        return (active, last + min(self.silence, self.lost_after))

    def _quiet_at(self, now: float) -> bool:
        """Under the lock: can the rule decide nothing at `now` (see _calm)?"""
        line, until = self._quiet
        return now < until and line == self.bus.active and self.unanswered[line] < SYNCS_UNANSWERED \
            and not self.lost and not self.pending

    def _lost_check(self, now: float) -> list[LineEvent]:
        """Under the lock: both lines silent beyond the switch's bound is the network lost."""
        heard = [t for t in self.line_last if t is not None]
        if heard and self.operational and not self.lost and now - max(heard) > self.lost_after:
            self.lost = True
            return [LineEvent(now, LINES_LOST, self.bus.active,
                              f"both bus lines lost: no node frame on line A or B for {now - max(heard):.3f} s")]
        return []

    def bridging(self, now: float | None = None) -> bool:
        """Is a switch under way (missing process data is the switch, not node loss)?"""
        now = self.clock() if now is None else now
        if not 0.0 <= now - self._checked_at < CHECKED_RECENTLY:
            self.check(now)     # a loss of both lines is reported before anyone judges the silence
        with self._lock:
            if self.lost:
                return False
            heard = [t for t in self.line_last if t is not None]
            if not heard or now - max(heard) > self.lost_after:
                return False
            return self.unanswered[self.bus.active] > 0 or (
                bool(self.pending) and now - self.switched_at < self.lost_after)

    def status(self) -> dict:
        now = self.clock()
        with self._lock:
            return {"active": LINE_NAMES[self.bus.active], "switches": self.switches,
                    "lost": self.lost, "bridged_cycles": self.bridged_cycles,
                    "heard_ago": {LINE_NAMES[i]: (None if t is None else round(now - t, 3))
                                  for i, t in enumerate(self.line_last)}}

    # ------------------------------------------------------------------ plumbing
    def _emit(self, events: list[LineEvent]) -> None:
        for event in events:
            self.events.append(event)
            if self.on_event is not None:
                try:
                    self.on_event(event)
                except Exception:
                    logger.exception("line event callback failed")

    def _run(self) -> None:
        due = time.monotonic() + TICK
        while not self._stop.wait(max(0.0, due - time.monotonic())):
            late = time.monotonic() - due
            due = time.monotonic() + TICK
            self.timer_pass(late)

    def timer_pass(self, late: float) -> None:
        """One pass of the timer, `late` s after it was due (an ArmNetwork's monitor runs it,
        standalone its own thread). A pass that wakes late (this process was starved: frames may
        wait unread) judges nothing; the time it lost is not silence of either line (as
        health.py does). Beside a lockstep controller (its clock counts SYNCs) a pass judges
        nothing either: where a wall-clock pass falls between two SYNCs follows the machine's
        speed, so the rule is judged at each SYNC (on_tx) and by bridging() in the cycle."""
        if self.clock is not time.monotonic:
            return
        if late > STARVED_SLACK:
            with self._lock:
                for line in (0, 1):
                    if self.line_last[line] is not None:
                        self.line_last[line] += late
                    for node in self.heard[line]:
                        self.heard[line][node] += late
            return
        now, seen = time.monotonic(), self._seen
        if not seen[0] and not seen[1]:
            # check()'s own path when nothing was noted and the rule is quiet, in one call (the
            # usual pass between two SYNCs' answers runs cold: its cost is what it touches)
            with self._lock:
                if not seen[0] and not seen[1] and self._quiet_at(now):
                    self._checked_at = now
                    return
        self.check(now)

    def stop(self) -> None:
        for observers, observer in ((self.bus.rx_observers, self.on_rx),
                                    (self.bus.tx_watch.get(od.SYNC_COB_ID_DEFAULT, []), self.on_tx)):
            if observer in observers:
                observers.remove(observer)
        if self.bus.standby_passes is standby_passes:
            self.bus.standby_passes = None
        if self.bus.rx_note is self._seen:
            self.bus.rx_note = None
        self._stop.set()
        if self._thread is not None:
            self._thread.join(1.0)


def attach(net) -> LineRedundancyMaster | None:
    """The master's rule for an ArmNetwork on a redundant pair (None on one line); its events
    become the network's events (`poll_events()`), with the line event's code as kind."""
    from spacearm.drivers.errors import NetworkEvent

    bus = net.network.bus
    if not hasattr(bus, "tx_router"):
        return None
    ids = {d.node_id for d in net.drivers.values()}
    # which node sends a COB-ID: its TPDOs (fixed at start), heartbeat, EMCY and SDO answers
    senders = {cob: route[0].node_id for cob, route in net._tpdo_routes.items()}
    senders.update({base + n: n for n in ids for base in (od.EMCY_BASE, od.SDO_TX_BASE, od.HEARTBEAT_BASE)})
    node_of = senders.get

    def on_event(event: LineEvent) -> None:
        network_event = NetworkEvent(event.code, "bus", 0, event.message)
        net._events.append(network_event)
        for callback in net.event_callbacks:
            callback(network_event)

    # lockstep: the rule runs on controller time (a SYNC period per cycle), as the nodes beside a
    # lockstep controller judge the master's heartbeat on SYNC time: a cycle that waits for a
    # silent line, or a process that waits for a core, is no time for either side
    period = net.controller_period
    clock = (lambda: net._sync * period) if period is not None else time.monotonic
    master = LineRedundancyMaster(
        bus, sorted(ids), node_of, node_period=max(n.heartbeat_period for n in net.config.nodes),
        master_period=net.config.bus.master_heartbeat_period, settings=settings_of(net.config), on_event=on_event,
        clock=clock, timer=False)     # the network's monitor thread runs its timer (timer_pass)
    net.line_redundancy = master
    return master

