"""Client of the simulator's fault-injection unit (spacearm.firmware_sim.control), over the bus.

Tests use it so fault scenarios run unchanged on every transport (the simulator may be in
another process). It shares the ArmNetwork's bus connection, not its SDO timeout: this unit is
test tooling, and a simulator process the machine starves answers it late (seen at load 12:
no answer within the bus's 0.5 s), which is no device fault and must not fail the scenario.

    rig = SimControl(net)                       # node ID 126 by default
    rig.silence("joint_3"); ...; rig.silence("joint_3", False)
"""
from __future__ import annotations

import canopen
from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

from spacearm.base.canopen import od
from spacearm.base.config.bus import EDS_DIR
from spacearm.base.canopen.eds import load_od
from spacearm.drivers.errors import DriverError, SdoError
from spacearm.drivers.network import ArmNetwork

CONTROL_TIMEOUT = 10.0     # s for the fault-injection unit's answer (module docstring)


class SimControl:
    def __init__(self, arm: ArmNetwork, node_id: int = od.SIM_CONTROL_NODE_DEFAULT):
        arm.connect()
        self.arm = arm
        self.label = f"node {node_id} 'sim_control' (fault injection)"
        self.node = canopen.RemoteNode(node_id, load_od(EDS_DIR / "sim_control.eds", node_id))
        self.node.sdo.RESPONSE_TIMEOUT = max(arm.config.bus.sdo_timeout, CONTROL_TIMEOUT)
        arm.network.add_node(self.node)
        for cob in (od.HEARTBEAT_BASE + node_id, od.EMCY_BASE + node_id):
            arm.network.unsubscribe(cob)
        arm.network.unsubscribe(od.NMT_COB_ID, self.node.nmt.on_command)   # ArmNetwork counts NMT frames

    def _write(self, index: int, sub: int, value: int, target: str | int | None = None) -> None:
        if target is not None:
            self._write(od.SIM_TARGET_NODE, 0, self.arm._driver(target).node_id)
        obj = self.node.object_dictionary[index]
        var = obj[sub] if hasattr(obj, "subindices") else obj
        try:
            self.node.sdo.download(index, sub, var.encode_raw(value))
        except SdoAbortedError as exc:
            raise SdoError(self.label, "write", index, sub, exc.code) from None
        except SdoCommunicationError as exc:
            raise DriverError(f"{self.label}: no answer (is the simulator started with --control-node?): "
                              f"{exc}") from None

    def silence(self, node: str | int, on: bool = True) -> None:
        """The node stops sending (heartbeat, PDOs, SDO answers) and ignores the bus."""
        self._write(od.SIM_SILENT, 0, int(on), node)

    def stop_heartbeat(self, node: str | int, on: bool = True) -> None:
        self._write(od.SIM_HEARTBEAT_STOPPED, 0, int(on), node)

    def abort_sdos(self, node: str | int, code: int | None) -> None:
        """Every SDO request to the node is aborted with this code (None: normal again)."""
        self._write(od.SIM_SDO_ABORT, 0, code or 0, node)

    def drop_tpdos(self, node: str | int, count: int) -> None:
        self._write(od.SIM_DROP_TPDOS, 0, count, node)

    def corrupt_tpdos(self, node: str | int, count: int) -> None:
        self._write(od.SIM_CORRUPT_TPDOS, 0, count, node)

    def ignore_sync(self, node: str | int, on: bool = True) -> None:
        self._write(od.SIM_IGNORE_SYNC, 0, int(on), node)

    def freeze(self, node: str | int, on: bool = True) -> None:
        """The node's sensor values stop updating; its TPDOs go on with the last values."""
        self._write(od.SIM_FREEZE, 0, int(on), node)

    def raise_fault(self, node: str | int, emcy_code: int) -> None:
        """The device detects a fault with this EMCY code (drives enter FAULT)."""
        self._write(od.SIM_RAISE_FAULT, 0, emcy_code, node)

    def stall(self, joint: str | int, on: bool = True) -> None:
        self._write(od.SIM_STALL, 0, int(on), joint)

    def set_temperature(self, joint: str | int, celsius: float) -> None:
        self._write(od.SIM_TEMPERATURE, 0, round(celsius * 10), joint)

    def power_cycle(self, node: str | int) -> None:
        self._write(od.SIM_POWER_CYCLE, 0, 1, node)

    def set_wrench(self, force: tuple[float, float, float], torque: tuple[float, float, float]) -> None:
        for i, value in enumerate((*force, *torque), start=1):
            self._write(od.SIM_WRENCH, i, round(value * 1000))

    def set_ee_target_present(self, present: bool) -> None:
        self._write(od.SIM_EE_TARGET_PRESENT, 0, int(present))
