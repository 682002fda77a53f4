"""CiA 402 power state machine: statusword decoding and controlword commands.

Shared by the controller-side driver (spacearm.drivers.cia402) and the simulated drive firmware.
"""
from __future__ import annotations

from enum import Enum


class State(str, Enum):
    NOT_READY_TO_SWITCH_ON = "NOT READY TO SWITCH ON"
    SWITCH_ON_DISABLED = "SWITCH ON DISABLED"
    READY_TO_SWITCH_ON = "READY TO SWITCH ON"
    SWITCHED_ON = "SWITCHED ON"
    OPERATION_ENABLED = "OPERATION ENABLED"
    QUICK_STOP_ACTIVE = "QUICK STOP ACTIVE"
    FAULT_REACTION_ACTIVE = "FAULT REACTION ACTIVE"
    FAULT = "FAULT"


# (mask, value, state), checked in order
_SW_PATTERNS = (
    (0x4F, 0x00, State.NOT_READY_TO_SWITCH_ON),
    (0x4F, 0x40, State.SWITCH_ON_DISABLED),
    (0x6F, 0x21, State.READY_TO_SWITCH_ON),
    (0x6F, 0x23, State.SWITCHED_ON),
    (0x6F, 0x27, State.OPERATION_ENABLED),
    (0x6F, 0x07, State.QUICK_STOP_ACTIVE),
    (0x4F, 0x0F, State.FAULT_REACTION_ACTIVE),
    (0x4F, 0x08, State.FAULT),
)

# statusword bits the state is encoded in, per state (bit 4 voltage enabled, bit 5 quick stop)
STATE_BITS = {
    State.NOT_READY_TO_SWITCH_ON: 0x00,
    State.SWITCH_ON_DISABLED: 0x40,
    State.READY_TO_SWITCH_ON: 0x31,
    State.SWITCHED_ON: 0x33,
    State.OPERATION_ENABLED: 0x37,
    State.QUICK_STOP_ACTIVE: 0x17,
    State.FAULT_REACTION_ACTIVE: 0x1F,
    State.FAULT: 0x08,
}

SW_VOLTAGE_ENABLED = 1 << 4
SW_QUICK_STOP = 1 << 5      # 0 = quick stop active
SW_WARNING = 1 << 7
SW_REMOTE = 1 << 9
SW_TARGET_REACHED = 1 << 10
SW_INTERNAL_LIMIT = 1 << 11
SW_OP_MODE_12 = 1 << 12     # PP: set-point acknowledge; CSP: drive follows the target
SW_FOLLOWING_ERROR = 1 << 13

# controlword commands (bits 0..3 and 7)
CW_SHUTDOWN = 0x0006
CW_SWITCH_ON = 0x0007
CW_DISABLE_VOLTAGE = 0x0000
CW_QUICK_STOP = 0x0002
CW_DISABLE_OPERATION = 0x0007
CW_ENABLE_OPERATION = 0x000F
CW_FAULT_RESET = 0x0080
CW_NEW_SETPOINT = 1 << 4    # PP
CW_CHANGE_IMMEDIATELY = 1 << 5
CW_RELATIVE = 1 << 6
CW_HALT = 1 << 8


def decode_statusword(statusword: int) -> State:
    for mask, value, state in _SW_PATTERNS:
        if statusword & mask == value:
            return state
    return State.NOT_READY_TO_SWITCH_ON


class Command(str, Enum):
    DISABLE_VOLTAGE = "disable voltage"
    QUICK_STOP = "quick stop"
    SHUTDOWN = "shutdown"
    SWITCH_ON = "switch on"
    ENABLE_OPERATION = "enable operation"


def decode_controlword(controlword: int) -> Command:
    if not controlword & 0x02:
        return Command.DISABLE_VOLTAGE
    if not controlword & 0x04:
        return Command.QUICK_STOP
    if not controlword & 0x01:
        return Command.SHUTDOWN
    if not controlword & 0x08:
        return Command.SWITCH_ON
    return Command.ENABLE_OPERATION
