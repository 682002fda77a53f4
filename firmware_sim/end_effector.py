"""Simulated end-effector controller: clamp/release (grip) and screwing (lock) axes.

Command (2100h): 0 none, 1 clamp and lock, 2 release, 3 stop, 4 fault reset. An SDO
write always executes; an RPDO executes when the value changes (so a cyclic RPDO can
hold the last command). The codes are spacearm.base.canopen.od.EeCommand (2100h) and EeState (2101h).
"""
from __future__ import annotations


from spacearm.base.canopen import od
from spacearm.base.canopen.od import EeCommand, EeState
from spacearm.firmware_sim.node import SimNode
from spacearm.firmware_sim.od_cyclic import CyclicObjects

STALL_TIMEOUT = 1.0   # s without progress while moving -> jam fault


# The codes as module constants: EeState.X is an Enum class attribute, ~0.1 us a lookup on
# Python 3.11 against ~0.01 us for a global, and a SYNC compares ~20 (issue 35)
OPEN, CLOSING, LOCKING, LOCKED, UNLOCKING, OPENING, STOPPED, FAULT = (
    EeState.OPEN, EeState.CLOSING, EeState.LOCKING, EeState.LOCKED, EeState.UNLOCKING, EeState.OPENING,
    EeState.STOPPED, EeState.FAULT)
CMD_CLAMP, CMD_RELEASE, CMD_STOP, CMD_FAULT_RESET, CMD_LATCH_LOCK, CMD_LATCH_UNLOCK = (
    EeCommand.CLAMP, EeCommand.RELEASE, EeCommand.STOP, EeCommand.FAULT_RESET, EeCommand.LATCH_LOCK,
    EeCommand.LATCH_UNLOCK)
_TORQUE_LIMIT_KEY, _LOCK_TURNS_KEY = (od.EE_SCREW_TORQUE_LIMIT, 0), (od.EE_LOCK_TURNS, 0)   # param() cache keys
MOVING = (CLOSING, LOCKING, UNLOCKING, OPENING)


class EndEffectorNode(SimNode):
    device_type = "end_effector"

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._actual_values = CyclicObjects(self, [(od.EE_STATE, 0), (od.EE_GRIP_POSITION, 0), (od.EE_SCREW_TORQUE, 0),
                                                   (od.EE_SCREW_TURNS, 0), (od.EE_FAULT_CODE, 0)])

    def reset_application(self) -> None:
        ee = self.plant.ee
        ee.grip_speed = ee.screw_speed = 0.0
        if ee.grip <= 0.0 and ee.turns <= 0.0:
            self.state = OPEN
        elif ee.grip >= 1.0 and ee.screw_torque > 0.0:
            self.state = LOCKED
        else:
            self.state = STOPPED
        self.pending: int | None = None
        self.last_rpdo_command = 0
        self.fault_code = 0
        self.stall_time = 0.0
        self.locked_torque = 0.0
        self._progress = (ee.grip, ee.turns)
        self._update_od()

    WRITE_REACTIONS = frozenset({od.EE_COMMAND})     # the only object on_write looks at

    def on_write(self, index: int, subindex: int, data: bytes) -> None:
        if index == od.EE_COMMAND:
            value = data[0] if data else 0
            if self.in_rpdo:
                if value == self.last_rpdo_command:
                    return
                self.last_rpdo_command = value
            self.pending = value

    def on_sync_begin(self, dt: float) -> None:
        cmd, self.pending = self.pending, None
        ee = self.plant.ee
        s = self.state
        if cmd == CMD_FAULT_RESET and s == FAULT and not ee.jammed:
            self.fault_code = 0
            self.state = STOPPED
            self.emcy(od.EMCY_NO_ERROR)
        elif s == FAULT:
            pass
        elif cmd == CMD_STOP and s in MOVING:
            self.state = STOPPED
        elif cmd == CMD_CLAMP and s in (OPEN, STOPPED, OPENING, UNLOCKING):
            self.state = CLOSING if ee.grip < 1.0 else LOCKING
        elif cmd == CMD_RELEASE and s in (LOCKED, STOPPED, LOCKING, CLOSING):
            self.state = UNLOCKING if ee.turns > 0.0 else OPENING
        elif cmd in (CMD_LATCH_UNLOCK, CMD_LATCH_LOCK) and s == LOCKED:
            drive_latch = getattr(self.plant.environment, "drive_latch", None)   # the contact world
            if drive_latch is not None:
                drive_latch(cmd == CMD_LATCH_LOCK)
        if self.state != s:
            self.stall_time = 0.0
        self._drive()

    def _drive(self) -> None:
        ee, p = self.plant.ee, self.plant.ee.params
        ee.grip_speed = ee.screw_speed = 0.0
        if self.state == CLOSING:
            ee.grip_speed = 1.0 / p.grip_close_time
        elif self.state == OPENING:
            ee.grip_speed = -1.0 / p.grip_close_time
        elif self.state == LOCKING:
            ee.screw_speed = p.screw_speed
        elif self.state == UNLOCKING:
            ee.screw_speed = -p.screw_speed

    def on_sync_end(self, dt: float) -> None:
        ee = self.plant.ee
        # param()'s cached values inline: a method call each, every SYNC (issue 35)
        params = self._params
        lock_torque = params.get(_TORQUE_LIMIT_KEY)
        lock_torque = (self.param(od.EE_SCREW_TORQUE_LIMIT) if lock_torque is None else lock_torque) / 1000.0
        lock_turns = params.get(_LOCK_TURNS_KEY)
        lock_turns = (self.param(od.EE_LOCK_TURNS) if lock_turns is None else lock_turns) / 1000.0
        if self.state in MOVING:
            progress = (ee.grip, ee.turns)
            self.stall_time = 0.0 if progress != self._progress else self.stall_time + dt
            self._progress = progress
            if self.stall_time > STALL_TIMEOUT:
                self._fault(od.EMCY_EE_JAM)
        if self.state == CLOSING and ee.grip >= 1.0:
            self.state = LOCKING
        elif self.state == LOCKING:
            if ee.screw_torque >= lock_torque:
                self.state = LOCKED
            elif ee.turns > 1.5 * lock_turns:
                self._fault(od.EMCY_EE_SCREW_TORQUE)   # no seat found: lock torque never reached
        elif self.state == UNLOCKING and ee.turns <= 0.0:
            self.state = OPENING
        elif self.state == OPENING and ee.grip <= 0.0:
            self.state = OPEN
        self._drive()
        self._update_od()

    def on_heartbeat_lost(self, producer: int) -> None:
        if self.state in MOVING:                # controller lost: stop where we are
            self.state = STOPPED
            self._drive()

    def _fault(self, code: int) -> None:
        self.state = FAULT
        self.fault_code = code
        self.emcy(code, od.ERR_REG_MANUFACTURER)

    def inject_fault(self, code: int = od.EMCY_EE_JAM, register_bits: int = 0) -> None:
        self._fault(code)

    def _update_od(self) -> None:
        ee = self.plant.ee
        self._actual_values.write((int(self.state), round(ee.grip * 1000),
                                   max(-32768, min(32767, round(ee.screw_torque * 1000))), round(ee.turns * 1000),
                                   self.fault_code))
