"""Non-blocking CiA 402 power state machine driver (controller side).

``Cia402Axis.step(statusword)`` is called once per cycle with the statusword of the
latest TPDO and returns the controlword to send in the next RPDO: one transition per
cycle, no sleeping, no polling. Goals: enable(), disable(), quick_stop(), fault_reset().
"""
from __future__ import annotations

from enum import Enum

from spacearm.base.canopen.cia402_defs import (CW_DISABLE_VOLTAGE, CW_ENABLE_OPERATION, CW_FAULT_RESET, CW_QUICK_STOP,
                                 CW_SHUTDOWN, CW_SWITCH_ON, State, decode_statusword)

FAULT_RESET_VERIFY_CYCLES = 5


class Goal(str, Enum):
    NONE = "none"              # leave the drive alone (controlword 0 = disable voltage)
    DISABLED = "disabled"      # switch on disabled
    READY = "ready"            # ready to switch on (shutdown)
    ENABLED = "enabled"        # operation enabled
    QUICK_STOP = "quick stop"


class Cia402Axis:
    def __init__(self, label: str = "axis"):
        self.label = label
        self.goal = Goal.NONE
        self.state = State.NOT_READY_TO_SWITCH_ON
        self.statusword = 0
        self.controlword = CW_DISABLE_VOLTAGE
        self._reset_phase = 0          # 0 idle, 1 bit 7 low, 2 bit 7 high (edge), 3.. verifying
        self._reset_cycles = 0
        self.fault_reset_failed = False
        self.fault_cleared = False     # set for one step after a successful reset

    # goals ----------------------------------------------------------------------
    def enable(self) -> None:
        self.goal = Goal.ENABLED

    def disable(self) -> None:
        self.goal = Goal.DISABLED

    def shutdown(self) -> None:
        self.goal = Goal.READY

    def quick_stop(self) -> None:
        self.goal = Goal.QUICK_STOP

    def fault_reset(self) -> None:
        """Start a fault reset (rising edge of controlword bit 7), verified over the next cycles."""
        self._reset_phase = 1
        self._reset_cycles = 0
        self.fault_reset_failed = False

    @property
    def enabled(self) -> bool:
        return self.state == State.OPERATION_ENABLED

    @property
    def fault(self) -> bool:
        return self.state in (State.FAULT, State.FAULT_REACTION_ACTIVE)

    @property
    def resetting(self) -> bool:
        return self._reset_phase != 0

    # one cycle --------------------------------------------------------------------
    def step(self, statusword: int) -> int:
        self.statusword = statusword
        self.fault_cleared = False
        if not self._reset_phase:
            # no fault reset running: state and controlword follow from the statusword and the
            # goal alone, worked out once per pair (a handful ever seen; issue 35)
            key = (statusword, self.goal)
            steady = _STEADY.get(key)
            if steady is None:
                state = decode_statusword(statusword)
                steady = _STEADY[key] = (state, self._next(state))
            self.state, self.controlword = steady
            return self.controlword
        self.state = s = decode_statusword(statusword)
        self.controlword = self._next(s)
        return self.controlword

    def _next(self, s: State) -> int:
        if self._reset_phase:
            if self._reset_phase == 1:
                if s == State.FAULT_REACTION_ACTIVE:
                    return CW_DISABLE_VOLTAGE          # the drive is still stopping: wait for FAULT
                self._reset_phase = 2
                return CW_DISABLE_VOLTAGE              # bit 7 low first, so the next is an edge
            if self._reset_phase == 2:
                self._reset_phase = 3
                return CW_FAULT_RESET
            # verifying: the statusword must leave FAULT
            if s not in (State.FAULT, State.FAULT_REACTION_ACTIVE):
                self._reset_phase = 0
                self.fault_cleared = True
            else:
                self._reset_cycles += 1
                if self._reset_cycles >= FAULT_RESET_VERIFY_CYCLES:
                    self._reset_phase = 0
                    self.fault_reset_failed = True
                return CW_DISABLE_VOLTAGE
        if s in (State.FAULT, State.FAULT_REACTION_ACTIVE, State.NOT_READY_TO_SWITCH_ON):
            return CW_DISABLE_VOLTAGE                 # wait for an explicit fault_reset()
        g = self.goal
        if g == Goal.NONE or g == Goal.DISABLED:
            return CW_DISABLE_VOLTAGE
        if g == Goal.QUICK_STOP:
            return CW_QUICK_STOP if s in (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE) else CW_DISABLE_VOLTAGE
        if g == Goal.READY:
            return CW_SHUTDOWN
        # Goal.ENABLED: one transition per cycle
        if s == State.SWITCH_ON_DISABLED:
            return CW_SHUTDOWN                        # -> ready to switch on
        if s == State.READY_TO_SWITCH_ON:
            return CW_SWITCH_ON                       # -> switched on
        if s == State.SWITCHED_ON:
            return CW_ENABLE_OPERATION                # -> operation enabled
        if s == State.QUICK_STOP_ACTIVE:
            return CW_DISABLE_VOLTAGE                 # leave quick stop via switch on disabled
        return CW_ENABLE_OPERATION                    # stay enabled


# (statusword, goal) -> (state, controlword) outside a fault reset, where _next changes nothing
_STEADY: dict[tuple[int, Goal], tuple[State, int]] = {}
