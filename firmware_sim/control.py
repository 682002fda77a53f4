"""Fault-injection unit of the simulated test rig: an SDO-only node (configs/eds/sim_control.eds)
through which a test in another process injects faults into the simulated nodes, so the
same fault scenarios run over every transport. Enabled by ``spacearm sim --control-node ID``
(or ``Simulator(control_node_id=ID)``); the controller side is ``spacearm.drivers.sim_control``.

Write 2F00h (target node ID) first; the other objects act on that node when written.
It has no NMT state, heartbeat or PDOs (it is not part of the arm).
"""
from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from canopen.sdo import SdoAbortedError

from spacearm.base.canopen import od
from spacearm.base.config.bus import EDS_DIR
from spacearm.base.canopen.eds import load_od
from spacearm.firmware_sim.sdo_server import NodeTx, SimLocalNode, name_the_object

if TYPE_CHECKING:
    from spacearm.firmware_sim.runner import Simulator

logger = logging.getLogger(__name__)

# data cannot be transferred: no such target node / not possible in the target's device type
from spacearm.base.canopen.codes import ABORT_DEVICE_STATE as ABORT_WRONG_DEVICE, ABORT_STORE as ABORT_NO_SUCH_NODE  # noqa: E402


class SimControlNode:
    def __init__(self, node_id: int, sim: "Simulator"):
        self.node_id = node_id
        self.name = "sim_control"
        self.sim = sim
        self.local = SimLocalNode(node_id, load_od(EDS_DIR / "sim_control.eds", node_id))
        self.local._write_callbacks.remove(self.local.nmt.on_write)
        self.local.sdo.network = NodeTx(self)
        self.local.add_write_callback(self._on_write)

    def send(self, can_id: int, data: bytes) -> None:
        self.sim._send(can_id, data)

    def on_sdo_request(self, data: bytes) -> None:
        if len(data) != 8:
            self.sim.stats.malformed += 1
            return
        name_the_object(self.local.sdo, data)
        self.local.sdo.on_request(od.SDO_RX_BASE + self.node_id, bytearray(data), 0.0)

    def _target(self):
        target = self.local.get_data(od.SIM_TARGET_NODE, 0)[0]
        node = self.sim.nodes.get(target)
        if node is None:
            raise SdoAbortedError(ABORT_NO_SUCH_NODE)
        return node

    def _on_write(self, index, subindex, od, data, **_):  # noqa: A002 - library keyword
        from spacearm.base.canopen import od as ids
        value = od.decode_raw(bytes(data))
        if index == ids.SIM_TARGET_NODE:
            if value not in self.sim.nodes:
                raise SdoAbortedError(ABORT_NO_SUCH_NODE)
            return
        if index == ids.SIM_WRENCH:
            self.sim.plant.wrench[subindex - 1] = value / 1000.0
            return
        if index == ids.SIM_EE_TARGET_PRESENT:
            ee = self.sim.plant.ee
            ee.params = ee.params.model_copy(update={"target_present": bool(value)})
            return
        node = self._target()
        f = node.faults
        with self.sim._sync_lock:
            if index == ids.SIM_SILENT:
                f.silent = bool(value)
            elif index == ids.SIM_HEARTBEAT_STOPPED:
                f.heartbeat_stopped = bool(value)
            elif index == ids.SIM_SDO_ABORT:
                f.sdo_abort = value or None
            elif index == ids.SIM_DROP_TPDOS:
                f.drop_tx = value
            elif index == ids.SIM_CORRUPT_TPDOS:
                f.corrupt_tx = value
            elif index == ids.SIM_IGNORE_SYNC:
                f.ignore_sync = bool(value)
            elif index == ids.SIM_FREEZE:
                f.frozen = bool(value)
            elif index == ids.SIM_RAISE_FAULT:
                node.inject_fault(value)
            elif index in (ids.SIM_STALL, ids.SIM_TEMPERATURE):
                joint = getattr(node, "joint", None)
                if joint is None:
                    raise SdoAbortedError(ABORT_WRONG_DEVICE)
                if index == ids.SIM_STALL:
                    joint.stalled = bool(value)
                else:
                    joint.temperature = value / 10.0
            elif index == ids.SIM_POWER_CYCLE:
                if value:
                    f.silent = False
                    node.power_on()
