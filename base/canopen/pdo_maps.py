"""Default PDO mappings of our simulated devices: firmware_sim/eds_builder.py writes them
into configs/eds/*.eds as the mapping defaults. The master does not read this module: it
takes a node's layout from its bus file ([nodes.pdo]) or, without one, from its EDS.

Each entry is (index, subindex, bits). RPDO n / TPDO n use the pre-defined connection set
COB-IDs (spacearm.base.canopen.od.RPDO_BASE / TPDO_BASE + node ID), transmission type 1 (every SYNC).
"""
from __future__ import annotations

from spacearm.base.canopen import od

Mapping = list[tuple[int, int, int]]

PDO_MAPS: dict[str, dict[str, list[Mapping]]] = {
    "joint_drive": {
        "rpdo": [[(od.CONTROLWORD, 0, 16), (od.TARGET_POSITION, 0, 32)],
                 [(od.VELOCITY_OFFSET, 0, 32), (od.TORQUE_OFFSET, 0, 16), (od.MODES_OF_OPERATION, 0, 8)]],
        "tpdo": [[(od.STATUSWORD, 0, 16), (od.POSITION_ACTUAL, 0, 32), (od.MODES_OF_OPERATION_DISPLAY, 0, 8)],
                 [(od.VELOCITY_ACTUAL, 0, 32), (od.TORQUE_ACTUAL, 0, 16), (od.ERROR_CODE, 0, 16)],
                 [(od.FOLLOWING_ERROR_ACTUAL, 0, 32), (od.DRIVE_TEMPERATURE, 0, 16), (od.BRAKE_STATUS, 0, 8)]],
    },
    "end_effector": {
        "rpdo": [[(od.EE_COMMAND, 0, 8)]],
        "tpdo": [[(od.EE_STATE, 0, 8), (od.EE_GRIP_POSITION, 0, 16), (od.EE_SCREW_TORQUE, 0, 16),
                  (od.EE_FAULT_CODE, 0, 16)],
                 [(od.EE_SCREW_TURNS, 0, 32)]],
    },
    "ft_sensor": {
        "rpdo": [[(od.FT_TARE, 0, 8)]],
        "tpdo": [[(od.FT_VALUES, 1, 16), (od.FT_VALUES, 2, 16), (od.FT_VALUES, 3, 16), (od.FT_STATUS, 0, 8)],
                 [(od.FT_VALUES, 4, 16), (od.FT_VALUES, 5, 16), (od.FT_VALUES, 6, 16)]],
    },
}
