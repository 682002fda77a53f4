"""The simulated nodes on a redundant pair of lines: each listens on one line and follows the
master's heartbeat to the other when it goes quiet (the slave's rule of ECSS-E-ST-50-15C
bus redundancy, as Lely's NMT redundancy manager implements it; the objects and the rule's
sources are in base/canopen/redundancy_object.py).

    sim = Simulator("virtual:arm-a+virtual:arm-b", bus_config).start()   # attaches LineSelection

Per node with the redundancy object (2E00h) and a master heartbeat consumer (1016h:1):

* it listens and sends on one line (selective bus access): starting on Bdefault;
* the master's heartbeat times out (1016h:1 time, through the node's own consumer check,
  which excuses the simulator's starvation) while the node is OPERATIONAL (our deviation from
  Lely, whose timer runs from the reset: a master busy configuring nodes by SDO may be late
  with its heartbeat, and a node leaving the line mid-configuration fails the boot; before
  OPERATIONAL the node neither toggles nor faults): after (Ttoggle - 1) more consumer times it
  toggles to the other line, counts Ctoggle, and sends its heartbeat there at once (as
  Lely's slave examples restart the producer on a switch, so the master sees it at once);
* no master there either: it toggles again every Ttoggle consumer times until Ctoggle
  reaches Ntoggle; then the line it is on becomes Bdefault, it stops toggling and takes its
  heartbeat-loss reaction (EMCY 8130h, a drive's fault reaction) as without redundancy;
* hearing the master again ends the search: that line becomes Bdefault.

A node without the object or without 1016h (the compact wrist drive) stays on line A.
Every toggle is a LineEvent in `events` (`spacearm sim` prints them).
"""
from __future__ import annotations

import time
from contextlib import nullcontext
from dataclasses import dataclass
from operator import attrgetter

from spacearm.base.canopen import od
from spacearm.base.canopen import redundancy_object as rdn
from spacearm.base.transport.redundant import LINE_NAMES, rx_line, rx_state

_TOGGLE_AT = attrgetter("toggle_at")
TICK = 0.002   # s: the toggle timer's resolution while a node searches (the simulator's timer runs it)


@dataclass(frozen=True)
class LineEvent:
    time: float        # monotonic (whatever clock the rule runs on)
    node: str
    kind: str          # "switch" | "no_master" | "master_found"
    line: int

    def __str__(self) -> str:
        return f"{self.node}: {self.kind} on line {LINE_NAMES[self.line]}"


class NodeLineRule:
    """The slave's rule for one node; times are passed in (monotonic s)."""

    def __init__(self, node):
        self.node = node
        # SimNode.param: cached until a write reaches the object (read for every master heartbeat)
        self._read = getattr(node, "param", None) or node.get
        self.line = self._get(rdn.BDEFAULT) & 1
        self.toggle_at: float | None = None
        self.searching = False

    def _get(self, sub: int) -> int:
        try:
            return int(self._read(rdn.REDUNDANCY, sub))
        except Exception:
            return rdn.DEFAULTS[sub]

    def master(self) -> tuple[int, float] | None:
        """(node ID, consumer time s) of the redundancy master (1016h:1), None if unset."""
        try:
            value = self._read(od.CONSUMER_HEARTBEAT, rdn.MASTER_CONSUMER_SUB)
        except Exception:
            return None
        producer, ms = (value >> 16) & 0x7F, value & 0xFFFF
        return (producer, ms / 1000.0) if producer and ms else None

    def master_heard(self) -> bool:
        """The master's heartbeat on this node's line: the search (if any) ends here."""
        self.toggle_at = None
        if not self.searching:
            return False
        self.searching = False
        self.node.put(rdn.REDUNDANCY, rdn.BDEFAULT, self.line)
        return True

    def master_missed(self, now: float, consumer_time: float) -> None:
        """The master's heartbeat timed out (one consumer time passed)."""
        ttoggle = self._get(rdn.TTOGGLE)
        if ttoggle == 0:          # Lely: Ttoggle 0 disables toggling
            return
        self.searching = True
        self.toggle_at = now + (ttoggle - 1) * consumer_time

    def due(self, now: float) -> bool:
        return self.toggle_at is not None and now >= self.toggle_at

    def toggle(self, now: float, consumer_time: float) -> str:
        """Switch to the other line; "switch", or "no_master" once Ntoggle is reached."""
        self.line ^= 1
        count = min(self._get(rdn.CTOGGLE) + 1, 255)
        self.node.put(rdn.REDUNDANCY, rdn.CTOGGLE, count)
        if count < self._get(rdn.NTOGGLE):
            self.toggle_at = now + self._get(rdn.TTOGGLE) * consumer_time
            return "switch"
        self.node.put(rdn.REDUNDANCY, rdn.BDEFAULT, self.line)
        self.toggle_at, self.searching = None, False
        return "no_master"


class _OnLineA:
    """A node without the redundancy object: always on line A."""
    line = 0


_ON_LINE_A = _OnLineA()

# the node's receive entry points a frame of the other line must not reach
_GATED = ("on_rpdo", "on_nmt", "on_sdo_request", "on_guard_request", "send_tpdos")


class LineSelection:
    """Selective bus access for every node of a Simulator whose bus is a RedundantBus."""

    def __init__(self, sim):
        self.sim = sim
        self.bus = sim.bus
        self.rules: dict[int, NodeLineRule] = {}
        self.events: list[LineEvent] = []
        self._owners: dict[int, object] = {}     # COB-ID -> its sending node's rule (found once)
        # per node, its entry points gated by line: installed only while frames of two lines
        # can reach the nodes (the pair turns them on and off: base/transport/rx_gating.py)
        self._gates: dict[int, dict[str, object]] = {}
        for node in sim.nodes.values():
            if rdn.REDUNDANCY in node.od and od.CONSUMER_HEARTBEAT in node.od:
                self.rules[node.node_id] = NodeLineRule(node)
            self._gate(node)
        self._rule_list = list(self.rules.values())     # (the rules are fixed here)
        self.bus.tx_router = self.tx_line
        self.bus.tx_owners = self._owners     # a burst looks its frames' lines up without a call
        self._lines_changed()
        self.bus.gate_receivers(self._set_gates)
        # no thread of its own: the simulator's timer runs timer_pass() (a thread more would cost
        # every pass of peer_timing's per-thread scan, and a wake-up every TICK)

    # ------------------------------------------------------------------ lines
    def _lines_changed(self) -> None:
        """After a node's line changed (a rule toggles only in timer_pass): the line every node
        is on, if one, lets a burst skip the look-up per frame (RedundantBus.tx_common_line)."""
        lines = {self.line_of(node) for node in self.sim.nodes.values()}
        self.bus.set_common_line(lines.pop() if len(lines) == 1 else None)

    def line_of(self, node) -> int:
        rule = self.rules.get(node.node_id)
        return rule.line if rule is not None else 0

    def hears(self, node) -> bool:
        """Does the frame this thread is delivering come on the line the node listens on?"""
        line = rx_line()
        return line is None or line == self.line_of(node)

    def tx_line(self, can_id: int) -> int | None:
        """The line a frame goes out on: its sending node's; None (both) for the simulator's
        own frames (its timing report, the fault-injection unit's answers)."""
        rule = self._owners.get(can_id)
        if rule is None:
            owner = self._sender(can_id)
            if owner is None:
                return None
            rule = self._owners[can_id] = self.rules.get(owner, _ON_LINE_A)
        return rule.line

    def _sender(self, can_id: int) -> int | None:
        function, node_id = can_id & 0x780, can_id & 0x7F
        if function in (od.EMCY_BASE, od.SDO_TX_BASE, od.HEARTBEAT_BASE) and node_id in self.sim.nodes:
            return node_id
        for node in self.sim.nodes.values():
            if any(pdo.cob_id == can_id for pdo in node._tpdos or ()):
                return node.node_id
        # a TPDO before the node built its PDO table (just after a reset): the pre-defined set
        if function in od.TPDO_BASE and node_id in self.sim.nodes:
            return node_id
        return None

    # ------------------------------------------------------------------ the node's side
    def _gate(self, node) -> None:
        self._gates[node.node_id] = {name: self._gated(node, getattr(node, name)) for name in _GATED}
        on_heartbeat = node.on_heartbeat

        rule = self.rules.get(node.node_id)
        own_line = rule if rule is not None else _ON_LINE_A
        rx = rx_state

        def heartbeat(producer: int, now: float) -> None:
            line = rx.line       # hears(node), inlined: every node, every master heartbeat
            if line is not None and line != own_line.line:
                return
            # only a node that searches or is due to toggle has anything to end here (master_heard)
            if rule is not None and (rule.searching or rule.toggle_at is not None):
                master = rule.master()
                if master is not None and producer == master[0] and rule.master_heard():
                    self.events.append(LineEvent(time.monotonic(), node.name, "master_found", rule.line))
            on_heartbeat(producer, now)

        def master_timed_out(producer: int, now: float) -> None:
            # the node's consumer check found a heartbeat timed out (nothing runs per timer pass:
            # issue 34, a wrapper around the check cost every node every pass); the master's is
            # the rule's to answer, not an EMCY's
            master = rule.master()
            if master is not None and producer == master[0]:
                if node.nmt_state == od.NMT_STATE_OPERATIONAL:
                    rule.master_missed(now, master[1])
                return
            timed_out(producer, now)

        node.on_heartbeat = heartbeat
        if rule is not None:        # without the rule the node's own reaction is all there is
            timed_out = node.consumer_timed_out
            node.consumer_timed_out = master_timed_out

    def _set_gates(self, on: bool) -> None:
        """The pair's call: gate the nodes' entry points (frames of either line may come) or
        not (every frame delivered is on the line every node listens on)."""
        for node in self.sim.nodes.values():
            gates = self._gates[node.node_id]
            if on:
                node.__dict__.update(gates)
            else:
                for name in gates:
                    node.__dict__.pop(name, None)

    def _gated(self, node, original):
        own_line = self.rules.get(node.node_id, _ON_LINE_A)
        rx = rx_state

        def gated(*args):       # hears(node), inlined: it runs for every frame a node gets
            line = rx.line
            if line is None or line == own_line.line:
                return original(*args)
            return None
        return gated

    def clock(self) -> float:
        """The simulator's clock for consumed heartbeats: the plant's (SYNC) time beside a
        lockstep controller (Simulator time_base 'sync'), else the monotonic clock."""
        return self.sim.plant.time if getattr(self.sim, "sync_time_base", False) else time.monotonic()

    def timer_pass(self, locked: bool = False) -> bool:
        """Toggle the nodes that are due: from the simulator's timer thread, and on the SYNC time
        base at every SYNC too (`locked`: the caller holds the simulator's SYNC lock). Returns
        whether a node still searches (the timer then runs every TICK)."""
        toggle_times = list(map(_TOGGLE_AT, self._rule_list))     # (in C: every timer pass runs it)
        if toggle_times.count(None) == len(toggle_times):
            return False        # the usual pass, no node due to toggle: nothing more than this
        now = self.clock()
        due = []
        for node_id, rule in self.rules.items():
            node = self.sim.nodes[node_id]
            if not rule.due(now) or not node.powered or node.faults.silent:
                continue
            master = rule.master()
            if master is None:
                rule.toggle_at = None
                continue
            due.append((node, rule, master))
        if not due:
            return any(rule.toggle_at is not None for rule in self._rule_list)
        # every node due toggles in one hold of the SYNC lock: a SYNC that takes the lock between
        # two toggles and is preempted there holds the nodes after it on the old line for as long
        # (likely a CI run's ft_sensor, the last node: 200 ms after the others, and lost)
        with nullcontext() if locked else self.sim._sync_lock:
            for node, rule, master in due:
                if not rule.due(now):
                    continue      # the master was heard meanwhile (its heartbeat takes no lock)
                kind = rule.toggle(now, master[1])
                self._lines_changed()
                self.events.append(LineEvent(time.monotonic(), node.name, "switch", rule.line))
                node.next_heartbeat = 0.0     # the producer restarts on the new line
                node.send_heartbeat()
                if kind == "no_master":
                    self.events.append(LineEvent(time.monotonic(), node.name, kind, rule.line))
                    node.emcy(od.EMCY_HEARTBEAT_ERROR, od.ERR_REG_COMMUNICATION, bytes([master[0]]))
                    node.on_heartbeat_lost(master[0])
        return any(rule.toggle_at is not None for rule in self._rule_list)


def attach(sim) -> LineSelection | None:
    """LineSelection for a simulator on a redundant pair (None on one line)."""
    return LineSelection(sim) if hasattr(sim.bus, "tx_router") else None
