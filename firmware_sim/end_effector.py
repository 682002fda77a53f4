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


MOVING = (EeState.CLOSING, EeState.LOCKING, EeState.UNLOCKING, EeState.OPENING)


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
            self.state = EeState.OPEN
        elif ee.grip >= 1.0 and ee.screw_torque > 0.0:
            self.state = EeState.LOCKED
        else:
            self.state = EeState.STOPPED
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
        if cmd == EeCommand.FAULT_RESET and s == EeState.FAULT and not ee.jammed:
            self.fault_code = 0
            self.state = EeState.STOPPED
            self.emcy(od.EMCY_NO_ERROR)
        elif s == EeState.FAULT:
            pass
        elif cmd == EeCommand.STOP and s in MOVING:
            self.state = EeState.STOPPED
        elif cmd == EeCommand.CLAMP and s in (EeState.OPEN, EeState.STOPPED, EeState.OPENING, EeState.UNLOCKING):
            self.state = EeState.CLOSING if ee.grip < 1.0 else EeState.LOCKING
        elif cmd == EeCommand.RELEASE and s in (EeState.LOCKED, EeState.STOPPED, EeState.LOCKING, EeState.CLOSING):
            self.state = EeState.UNLOCKING if ee.turns > 0.0 else EeState.OPENING
        elif cmd in (EeCommand.LATCH_UNLOCK, EeCommand.LATCH_LOCK) and s == EeState.LOCKED:
            drive_latch = getattr(self.plant.environment, "drive_latch", None)   # the contact world
            if drive_latch is not None:
                drive_latch(cmd == EeCommand.LATCH_LOCK)
        if self.state != s:
            self.stall_time = 0.0
        self._drive()

    def _drive(self) -> None:
        ee, p = self.plant.ee, self.plant.ee.params
        ee.grip_speed = ee.screw_speed = 0.0
        if self.state == EeState.CLOSING:
            ee.grip_speed = 1.0 / p.grip_close_time
        elif self.state == EeState.OPENING:
            ee.grip_speed = -1.0 / p.grip_close_time
        elif self.state == EeState.LOCKING:
            ee.screw_speed = p.screw_speed
        elif self.state == EeState.UNLOCKING:
            ee.screw_speed = -p.screw_speed

    def on_sync_end(self, dt: float) -> None:
        ee = self.plant.ee
        lock_torque = self.param(od.EE_SCREW_TORQUE_LIMIT) / 1000.0
        lock_turns = self.param(od.EE_LOCK_TURNS) / 1000.0
        if self.state in MOVING:
            progress = (ee.grip, ee.turns)
            self.stall_time = 0.0 if progress != self._progress else self.stall_time + dt
            self._progress = progress
            if self.stall_time > STALL_TIMEOUT:
                self._fault(od.EMCY_EE_JAM)
        if self.state == EeState.CLOSING and ee.grip >= 1.0:
            self.state = EeState.LOCKING
        elif self.state == EeState.LOCKING:
            if ee.screw_torque >= lock_torque:
                self.state = EeState.LOCKED
            elif ee.turns > 1.5 * lock_turns:
                self._fault(od.EMCY_EE_SCREW_TORQUE)   # no seat found: lock torque never reached
        elif self.state == EeState.UNLOCKING and ee.turns <= 0.0:
            self.state = EeState.OPENING
        elif self.state == EeState.OPENING and ee.grip <= 0.0:
            self.state = EeState.OPEN
        self._drive()
        self._update_od()

    def on_heartbeat_lost(self, producer: int) -> None:
        if self.state in MOVING:                # controller lost: stop where we are
            self.state = EeState.STOPPED
            self._drive()

    def _fault(self, code: int) -> None:
        self.state = EeState.FAULT
        self.fault_code = code
        self.emcy(code, od.ERR_REG_MANUFACTURER)

    def inject_fault(self, code: int = od.EMCY_EE_JAM, register_bits: int = 0) -> None:
        self._fault(code)

    def _update_od(self) -> None:
        ee = self.plant.ee
        self._actual_values.write((int(self.state), round(ee.grip * 1000),
                                   max(-32768, min(32767, round(ee.screw_torque * 1000))), round(ee.turns * 1000),
                                   self.fault_code))
