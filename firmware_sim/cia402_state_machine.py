"""The simulated drive's CiA 402 power state machine: the state a controlword command leads
to (CiA 402-2 transitions 2-12 and 16), with the quick stop option code 605Ah deciding 11
and 16. Transition 1 happens at reset and the fault transitions 13-15 come from what the
drive detects, so those stay with the drive (joint_drive.JointDriveNode), as does what a
transition sets going (a ramp, the brake).
"""
from __future__ import annotations

from spacearm.base.canopen.cia402_defs import Command, State

_TRANSITIONS: dict[tuple[State, Command], State] = {
    (State.SWITCH_ON_DISABLED, Command.SHUTDOWN): State.READY_TO_SWITCH_ON,            # 2
    (State.READY_TO_SWITCH_ON, Command.SWITCH_ON): State.SWITCHED_ON,                  # 3
    (State.READY_TO_SWITCH_ON, Command.ENABLE_OPERATION): State.OPERATION_ENABLED,     # 3 + 4
    (State.READY_TO_SWITCH_ON, Command.DISABLE_VOLTAGE): State.SWITCH_ON_DISABLED,     # 7
    (State.READY_TO_SWITCH_ON, Command.QUICK_STOP): State.SWITCH_ON_DISABLED,          # 7
    (State.SWITCHED_ON, Command.ENABLE_OPERATION): State.OPERATION_ENABLED,            # 4
    (State.SWITCHED_ON, Command.SHUTDOWN): State.READY_TO_SWITCH_ON,                   # 6
    (State.SWITCHED_ON, Command.DISABLE_VOLTAGE): State.SWITCH_ON_DISABLED,            # 10
    (State.SWITCHED_ON, Command.QUICK_STOP): State.SWITCH_ON_DISABLED,                 # 10
    (State.OPERATION_ENABLED, Command.SWITCH_ON): State.SWITCHED_ON,                   # 5
    (State.OPERATION_ENABLED, Command.SHUTDOWN): State.READY_TO_SWITCH_ON,             # 8
    (State.OPERATION_ENABLED, Command.DISABLE_VOLTAGE): State.SWITCH_ON_DISABLED,      # 9
    (State.OPERATION_ENABLED, Command.QUICK_STOP): State.QUICK_STOP_ACTIVE,            # 11
    (State.QUICK_STOP_ACTIVE, Command.DISABLE_VOLTAGE): State.SWITCH_ON_DISABLED,      # 12
    (State.QUICK_STOP_ACTIVE, Command.ENABLE_OPERATION): State.OPERATION_ENABLED,      # 16
}

# 605Ah: 0 disables the drive function at once (no quick stop active); 5-8 stay in quick
# stop active at rest, from which enable operation returns (transition 16)
QUICK_STOP_POWER_OFF = 0
QUICK_STOP_OPTIONS_STAYING = (5, 6, 7, 8)


def next_state(state: State, command: Command, quick_stop_option: int) -> State:
    """The state `command` leads to from `state` (itself when the command means nothing there)."""
    new = _TRANSITIONS.get((state, command), state)
    if new is State.QUICK_STOP_ACTIVE and state is State.OPERATION_ENABLED \
            and quick_stop_option == QUICK_STOP_POWER_OFF:
        return State.SWITCH_ON_DISABLED
    if state is State.QUICK_STOP_ACTIVE and new is State.OPERATION_ENABLED \
            and quick_stop_option not in QUICK_STOP_OPTIONS_STAYING:
        return state
    return new
