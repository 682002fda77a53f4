"""A simulator and a master on a redundant pair of in-process lines, paced like the daemon's
real-time cycle (a SYNC every sync period, a TPDO wait of one period)."""
from __future__ import annotations

import time
import uuid
from dataclasses import dataclass

import pytest

from spacearm.base.config.bus import load_bus_config
from spacearm.base.transport.line_faults import clear_all, line_fault
from spacearm.drivers import line_redundancy
from spacearm.drivers.network import ArmNetwork
from spacearm.firmware_sim import line_selection
from spacearm.firmware_sim.runner import Simulator


@dataclass
class Pair:
    lines: tuple[str, str]
    sim: Simulator
    selection: line_selection.LineSelection
    net: ArmNetwork
    master: line_redundancy.LineRedundancyMaster
    events: list
    starved_at_cut: float = 0.0

    def cut(self, line: int, mode: str = "cut", **kw) -> float:
        self.starved_at_cut = self.starved()
        line_fault(self.lines[line]).set(mode, **kw)
        return time.monotonic()

    def starved(self) -> float:
        """s the simulator's and the master's timers were starved or held so far (not silence)."""
        return self.sim.stats.starved_time + self.sim.stats.held_time + self.net.stats.starved_time

    def within_heartbeat_periods(self, took: float, periods: float = 3.0) -> bool:
        """The switch took at most `periods` node heartbeat periods of time the processes could
        observe (starvation since the cut is excused, as the node-loss bound does); printed."""
        period = max(n.heartbeat_period for n in self.net.config.nodes)
        starved = self.starved() - self.starved_at_cut
        print(f"switch {1e3 * took:.0f} ms = {took / period:.2f} heartbeat periods "
              f"(starved {1e3 * starved:.0f} ms)")
        return took - starved <= periods * period

    def restore(self, line: int) -> None:
        line_fault(self.lines[line]).clear()

    def run(self, seconds: float) -> list:
        """Cycle paced at the SYNC period; returns the network events of that time."""
        period = self.net.config.bus.sync_period
        end = time.monotonic() + seconds
        next_cycle = time.monotonic()
        while time.monotonic() < end:
            self.net.cycle(timeout=period)
            self.events += self.net.poll_events()
            next_cycle += period
            time.sleep(max(0.0, next_cycle - time.monotonic()))
        return self.events

    def node_lines(self) -> dict[str, int]:
        return {self.sim.nodes[i].name: r.line for i, r in self.selection.rules.items()}


@pytest.fixture
def pair():
    tag = uuid.uuid4().hex[:8]
    lines = (f"virtual:rdn-a-{tag}", f"virtual:rdn-b-{tag}")
    spec = "+".join(lines)
    config = line_redundancy.bus_config_for(spec, load_bus_config())   # what the daemon's network runs
    # bring-up under load is not what these tests judge: an SDO answer late behind a starved
    # simulator thread (seen: 0.8 s of starvation) must not fail the boot
    config = config.model_copy(update={"bus": config.bus.model_copy(update={"sdo_timeout": 3.0})})
    sim = Simulator(spec, config).start()
    selection = sim.line_selection
    net = ArmNetwork(spec, config)
    net.connect()
    master = net.line_redundancy
    try:
        net.boot()          # configures the nodes' redundancy objects
        net.enable_all()
        yield Pair(lines, sim, selection, net, master, [])
    finally:
        master.stop()
        net.close()
        sim.stop()
        clear_all()
