"""Simulated CiA 402 joint drive: power state machine, CSP and profile position modes,
servo loop on the shared plant joint, following-error window, software position and
velocity limits, torque limit, holding brake, drive temperature.

Stopping as CiA 402 drives do: quick stop (605Ah option 1/5 on the slow-down ramp 6084h, 2/6
on the quick-stop ramp 6085h; 1/2 then switch on disabled, 5/6 stay in quick stop active,
0 power off at once), halt (6040h bit 8, 605Dh 1: 6084h, 2: 6085h; stays enabled) and the
fault reaction (605Eh 0: power off, 1: 6084h, 2: 6085h). A ramp starts from the joint's
measured position and speed, never from the interpolator's reference, whose speed in CSP
carries the velocity offset on top of the position steps (twice the motion's speed). The
power-off brake closes BRAKE_ENGAGE_TIME after the drive lets go; on a controlled stop
the drive holds the joint at rest until it has, then leaves operation.

Controlword/target values are latched at SYNC (synchronous RPDOs, CiA 301 transmission
type 1); then the plant advances one SYNC period with this drive's servo loop running at
the plant's sub-step rate; then the actual values are written to the OD and sampled
into the TPDOs.
"""
from __future__ import annotations

import math

from spacearm.base.canopen import od
from spacearm.base.canopen.cia402_defs import (CW_CHANGE_IMMEDIATELY, CW_FAULT_RESET, CW_HALT, CW_NEW_SETPOINT, CW_RELATIVE,
                                 STATE_BITS, SW_FOLLOWING_ERROR, SW_INTERNAL_LIMIT, SW_OP_MODE_12, SW_REMOTE,
                                 SW_TARGET_REACHED, SW_WARNING, Command, State, decode_controlword)
from canopen.sdo import SdoAbortedError

from spacearm.base.canopen.axis_scale import FEED_UNIT
from spacearm.base.canopen.codes import ABORT_VALUE_INVALID

from spacearm.firmware_sim.cia402_state_machine import next_state
from spacearm.firmware_sim.node import SimNode
from spacearm.firmware_sim.od_cyclic import CyclicObjects
from spacearm.firmware_sim import simcore
from spacearm.firmware_sim.simcore import SERVO_CSP, SERVO_OFF
# the commands in the order of the core's stay masks (decode_controlword's order), and the masks
# worked out per (state, quick-stop option): bit i set when command i leaves the state as it is
_COMMANDS = (Command.DISABLE_VOLTAGE, Command.QUICK_STOP, Command.SHUTDOWN, Command.SWITCH_ON,
             Command.ENABLE_OPERATION)
_STAY: dict = {}

OVER_TEMPERATURE = 85.0   # degC: drive faults above this
WARN_TEMPERATURE = 75.0

# Spring-applied holding brake: from power off (or a controlled stop's request) to holding.
# Our choice for the ORU test bed's joint brakes (the paper names the brake, not its timing).
BRAKE_ENGAGE_TIME = 0.03  # s
HALT_OPTION = 0x605D      # not in every EDS: absent, halt uses the slow-down ramp (option 1)

# The states as module constants: State.X is an Enum class attribute, ~0.1 us a lookup on
# Python 3.11 against ~0.01 us for a global, and a drive's steady SYNC compares ~6 (issue 35)
OPERATION_ENABLED, QUICK_STOP_ACTIVE, FAULT_REACTION_ACTIVE, FAULT, SWITCH_ON_DISABLED = (
    State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE, State.FAULT_REACTION_ACTIVE, State.FAULT, State.SWITCH_ON_DISABLED)
ENERGISED = (OPERATION_ENABLED, QUICK_STOP_ACTIVE, FAULT_REACTION_ACTIVE)
# per state, the core's SYNC-end flags that follow from it (energised, enabled, fault reaction,
# quick stop: _simcore.c END_*) and its statusword bits: one lookup, not five comparisons a SYNC
_END_FLAGS = {state: ((state in ENERGISED) | (state == OPERATION_ENABLED) << 1 | (state == FAULT_REACTION_ACTIVE) << 2
                      | (state == QUICK_STOP_ACTIVE) << 3, STATE_BITS[state]) for state in State}


class JointDriveNode(SimNode):
    device_type = "joint_drive"

    def __init__(self, node_id, eds_path, name, plant, joint_index: int):
        self.joint = plant.joints[joint_index]
        super().__init__(node_id, eds_path, name, plant)
        servo = self._servo
        self.joint.controller = servo
        self.joint.period_servo = (servo, self._period_law)
        self._begin_objects = self._core_objects()
        self._actual_values = CyclicObjects(self, [
            (od.STATUSWORD, 0), (od.MODES_OF_OPERATION_DISPLAY, 0), (od.POSITION_ACTUAL, 0), (od.POSITION_DEMAND, 0),
            (od.VELOCITY_ACTUAL, 0), (od.TORQUE_ACTUAL, 0), (od.FOLLOWING_ERROR_ACTUAL, 0), (od.DRIVE_TEMPERATURE, 0),
            (od.BRAKE_STATUS, 0), (od.ERROR_CODE, 0)])

    # ------------------------------------------------------------------ state
    def reset_application(self) -> None:
        self.state = SWITCH_ON_DISABLED   # transition 1 happens by itself
        self.prev_cw = 0
        self.error_code = 0
        self.q_ref = self.joint.q_measured      # reference at the end of the period (rad)
        self.q_start = self.q_ref
        self.v_ref = 0.0
        self.v_ff = 0.0
        self.limit_active = False
        self.fe_time = 0.0
        self.following_error = False
        self.pp_target = None
        self.pp_ack = False
        self.target_reached = True
        self.mode = od.MODE_CSP
        self.prev_cw_setpoint = False
        self.pp_halt = False
        self.q_end = self.q_ref
        self.torque_ff = 0.0
        self.halt = False
        self.ramp_quick = True                 # the ramp running is 6085h's (else 6084h's)
        self._ramp_from_actual = False         # the next servo step starts the ramp from the measurement
        # s the brake has been closing (power off / stop done): it starts closed, as a power-off
        # brake is, so an unpowered joint never slips in the first SYNCs after power-on
        self.brake_closing = BRAKE_ENGAGE_TIME
        self.joint.brake_engaged = True
        self._update_od()

    WRITE_REACTIONS = frozenset({od.MODES_OF_OPERATION})     # the only object on_write looks at
    PURE_WRITE_CHECK = True      # on_write only checks its arguments (SimNode.pure_write_check)

    def on_write(self, index: int, subindex: int, data: bytes) -> None:
        if index == od.MODES_OF_OPERATION and int.from_bytes(data, "little", signed=True) not in (
                od.MODE_CSP, od.MODE_PROFILE_POSITION):
            raise SdoAbortedError(ABORT_VALUE_INVALID)      # value range: only CSP (8) and PP (1) supported

    def on_heartbeat_lost(self, producer: int) -> None:
        """Controller lost: fault reaction (quick-stop ramp, then brake)."""
        self._fault(od.EMCY_HEARTBEAT_ERROR, od.ERR_REG_COMMUNICATION, emcy=False)

    def inject_fault(self, code: int = od.EMCY_GENERIC, register_bits: int = 0) -> None:
        """Fault injection: the drive detects an error of this EMCY code."""
        self._fault(code, register_bits)

    # ------------------------------------------------------------------ scaling
    def _scale(self) -> float:
        """Increments per joint radian from 608Fh and 6091h; per metre on a linear axis (a
        prismatic plant joint), whose shaft revolution is 6092h's feed (axis_scale.py)."""
        enc = self.param(od.POSITION_ENCODER_RESOLUTION, 1) / self.param(od.POSITION_ENCODER_RESOLUTION, 2)
        gear = self.param(od.GEAR_RATIO, 1) / self.param(od.GEAR_RATIO, 2)
        if not self.joint.params.prismatic:
            return enc * gear / (2.0 * math.pi)
        return enc * gear / (self.param(od.FEED_CONSTANT, 1) * FEED_UNIT / self.param(od.FEED_CONSTANT, 2))

    def _rated_torque(self) -> float:
        return self.param(od.MOTOR_RATED_TORQUE) / 1000.0   # mN m -> N m (motor side)

    def _settings(self) -> tuple:
        """(k, rated torque, max motor torque, quick-stop and slow-down decelerations, following
        error window, quick-stop option, following error timeout, the software position limits'
        and maximum profile velocity's counts): the settings every SYNC reads, derived again
        only after a write or a reset dropped a cached value (ParamCache.epoch)."""
        key = (self._params.epoch, self.joint.params)
        if self._settings_key != key:
            k, rated = self._scale(), self._rated_torque()
            self._settings_values = (k, rated, self.param(od.MAX_TORQUE) / 1000.0 * rated,
                                     self.param(od.QUICK_STOP_DECELERATION) / k,
                                     self.param(od.PROFILE_DECELERATION) / k,
                                     self.param(od.FOLLOWING_ERROR_WINDOW) / k, self.param(od.QUICK_STOP_OPTION),
                                     *self._optional_settings())
            self._settings_key = (self._params.epoch, self.joint.params)
        return self._settings_values

    def _optional_settings(self) -> tuple:
        """The following error timeout and the limits' counts for _settings; None for those the
        EDS lacks: read where they are used, which raises as it did before they were kept."""
        try:
            timeout = self.param(od.FOLLOWING_ERROR_TIMEOUT)
        except SdoAbortedError:
            timeout = None
        try:
            limits = (self.param(od.SOFTWARE_POSITION_LIMIT, 1), self.param(od.SOFTWARE_POSITION_LIMIT, 2),
                      self.param(od.MAX_PROFILE_VELOCITY))
        except SdoAbortedError:
            limits = None
        return timeout, limits

    _settings_key = None

    # ------------------------------------------------------------------ SYNC
    def on_sync_begin(self, dt: float) -> None:
        self._dt = dt
        self._h = dt / self.plant.config.substeps
        key = self._settings_key       # _settings' usual answer inline: every drive, every SYNC
        settings = self._settings_values if key is not None and key[0] == self._params.epoch \
            and key[1] is self.joint.params else self._settings()
        k, rated, max_motor_torque, self.qs_dec, self.slow_dec, self._fe_window, self._qs_option = settings[:7]
        self._k = k
        core = simcore.core
        if core is not None and self._begin_objects is not None and not self.local._read_callbacks \
                and self._steady_begin(core, dt, k, rated, max_motor_torque, settings[8]):
            return
        cw = self.get(od.CONTROLWORD)
        self._apply_controlword(cw)
        mode = self.get(od.MODES_OF_OPERATION)
        if mode in (od.MODE_CSP, od.MODE_PROFILE_POSITION) and mode != self.mode:
            self.mode = mode
            self.q_ref = self.q_start = self.joint.q_measured
            self.v_ref = 0.0
            self.pp_target = None
        self.joint.max_motor_torque = max_motor_torque
        self.torque_ff = self.get(od.TORQUE_OFFSET) / 1000.0 * rated
        self.limit_active = False
        self.q_start = self.q_ref
        if self.state == OPERATION_ENABLED:
            lo = self.param(od.SOFTWARE_POSITION_LIMIT, 1) / k
            hi = self.param(od.SOFTWARE_POSITION_LIMIT, 2) / k
            vmax = self.param(od.MAX_PROFILE_VELOCITY) / k
            if self.mode == od.MODE_CSP:
                target = self.get(od.TARGET_POSITION) / k
                clamped = min(hi, max(lo, target))
                step = clamped - self.q_start
                if abs(step) > vmax * dt:
                    step = math.copysign(vmax * dt, step)
                self.limit_active = clamped != target or self.q_start + step != clamped
                self.q_end = self.q_start + step
                self.v_ff = step / dt + self.get(od.VELOCITY_OFFSET) / k
            else:  # profile position
                new_sp = cw & CW_NEW_SETPOINT and not self.prev_cw_setpoint
                if new_sp and (self.pp_target is None or self.target_reached or cw & CW_CHANGE_IMMEDIATELY):
                    target = self.get(od.TARGET_POSITION) / k
                    if cw & CW_RELATIVE:
                        target += self.pp_target if self.pp_target is not None else self.q_ref
                    self.pp_target = min(hi, max(lo, target))
                    self.limit_active = self.pp_target != target
                    self.target_reached = False
                    self.pp_ack = True
                if not cw & CW_NEW_SETPOINT:
                    self.pp_ack = False
                self.pp_halt = bool(cw & CW_HALT)
                self.pp_v = min(vmax, self.param(od.PROFILE_VELOCITY) / k)
                self.pp_a = self.param(od.PROFILE_ACCELERATION) / k
                self.pp_d = self.param(od.PROFILE_DECELERATION) / k
        self.prev_cw_setpoint = bool(cw & CW_NEW_SETPOINT)
        halt = bool(cw & CW_HALT) and self.state == OPERATION_ENABLED and self.mode == od.MODE_CSP
        if halt and not self.halt:
            option = self.param(HALT_OPTION) if HALT_OPTION in self.od else 1
            self._start_ramp(quick=option == 2)
        self.halt = halt
        self.ramp_dec = self.qs_dec if self.ramp_quick else self.slow_dec

    def _steady_begin(self, core, dt: float, k: float, rated: float, max_motor_torque: float, limits: tuple) -> bool:
        """The rest of on_sync_begin in the compiled core, for a SYNC that changes no state (no
        transition, mode change or halt starting; CSP when enabled). False: it was not such a
        SYNC, nothing changed. limits: the software position limits' and maximum profile
        velocity's counts (_settings)."""
        state = self.state
        enabled = state == OPERATION_ENABLED
        if not enabled:
            limits = (0, 0, 0)
        elif limits is None:
            limits = (self.param(od.SOFTWARE_POSITION_LIMIT, 1), self.param(od.SOFTWARE_POSITION_LIMIT, 2),
                      self.param(od.MAX_PROFILE_VELOCITY))
        stay = _STAY.get((state, self._qs_option))
        if stay is None:
            stay = _STAY[(state, self._qs_option)] = sum(1 << i for i, command in enumerate(_COMMANDS)
                                                          if next_state(state, command, self._qs_option) == state)
        steady = core.steady_begin(self.local.data_store, self._begin_objects, self.q_ref, dt, k, *limits, rated,
                                   enabled, state == FAULT, self.mode, stay, self.halt)
        if steady is None:
            return False
        cw, self.halt, self.torque_ff, self.limit_active, q_end, v_ff = steady
        if enabled:
            self.q_end, self.v_ff = q_end, v_ff
        self.prev_cw = cw
        self.joint.max_motor_torque = max_motor_torque
        self.q_start = self.q_ref
        self.prev_cw_setpoint = bool(cw & CW_NEW_SETPOINT)
        self.ramp_dec = self.qs_dec if self.ramp_quick else self.slow_dec
        return True

    def _core_objects(self) -> tuple | None:
        """(index, sub, bytes, signed) of the objects steady_begin reads from the data store, in
        its order; None if one is not a plain integer of the EDS (the Python path decodes it)."""
        objects = []
        for index in (od.CONTROLWORD, od.MODES_OF_OPERATION, od.TORQUE_OFFSET, od.TARGET_POSITION,
                      od.VELOCITY_OFFSET):
            try:
                _, codec, integer = self._codec(index, 0)
            except SdoAbortedError:          # not in this EDS
                return None
            kind = codec.format[-1:] if codec is not None and integer else ""
            if kind not in ("b", "B", "h", "H", "l", "L") or codec.size not in (1, 2, 4):
                return None
            objects.append((index, 0, codec.size, kind.islower()))
        return tuple(objects)

    def _start_ramp(self, quick: bool) -> None:
        self.ramp_quick = quick
        self._ramp_from_actual = True

    def _servo(self, s: float, q_meas: float, qd: float) -> float:
        """Position loop at the sub-step rate; returns motor torque (N m)."""
        if self.state not in ENERGISED:
            self.q_ref = q_meas
            self.v_ref = 0.0
            return 0.0
        h = self._h
        if self.state in (QUICK_STOP_ACTIVE, FAULT_REACTION_ACTIVE) or self.halt or \
                (self.mode == od.MODE_PROFILE_POSITION and self.pp_halt):
            if self._ramp_from_actual:
                self._ramp_from_actual = False
                self.q_ref, self.v_ref = q_meas, qd
            dv = (self.ramp_dec if self.state != OPERATION_ENABLED or self.halt else self.pp_d) * h
            self.v_ref = 0.0 if abs(self.v_ref) <= dv else self.v_ref - math.copysign(dv, self.v_ref)
            self.q_ref += self.v_ref * h
        elif self.mode == od.MODE_CSP:
            self.q_ref = self.q_start + s * (self.q_end - self.q_start)
            self.v_ref = self.v_ff
        else:
            if self.pp_target is not None:
                rem = self.pp_target - self.q_ref
                a = self.pp_a if abs(self.v_ref) < 1e-12 or rem * self.v_ref > 0 else self.pp_d
                v_des = math.copysign(min(self.pp_v, math.sqrt(2.0 * self.pp_d * abs(rem))), rem)
                dv = max(-a * h, min(a * h, v_des - self.v_ref))
                self.v_ref += dv
                if abs(rem) <= abs(self.v_ref) * h or abs(rem) < 1e-9:
                    self.q_ref, self.v_ref = self.pp_target, 0.0
                else:
                    self.q_ref += self.v_ref * h
        return servo_torque(self.joint, self.q_ref, self.v_ref, q_meas, qd) + self.torque_ff

    def _period_law(self) -> tuple | None:
        """_servo() for the whole period as the compiled core runs it (plant.JointModel.
        _core_period): powered off, or CSP in operation without halt; None for the states the
        core does not model (ramps, halt, profile position), which _servo() runs sub-step by
        sub-step."""
        state = self.state
        if state not in ENERGISED:
            kind = SERVO_OFF
        elif state == OPERATION_ENABLED and not self.halt and self.mode == od.MODE_CSP:
            kind = SERVO_CSP
        else:
            return None
        return kind, self.q_start, self.q_end, self.v_ff, self.torque_ff, self._end_period

    def _end_period(self, q_ref: float, v_ref: float) -> None:
        self.q_ref, self.v_ref = q_ref, v_ref

    def on_sync_end(self, dt: float) -> None:
        core = simcore.core
        if core is not None and self.mode == od.MODE_CSP and self._steady_end(core, dt):
            return
        j = self.joint
        self._stop_and_brake(dt)
        # following error (CSP and PP while enabled)
        q_measured = j.q_measured
        err = self.q_ref - q_measured
        window = self._fe_window
        if self.state == OPERATION_ENABLED and abs(err) > window:
            self.fe_time += dt
            self.following_error = True
            if self.fe_time * 1000.0 > self.param(od.FOLLOWING_ERROR_TIMEOUT):
                self._fault(od.EMCY_FOLLOWING_ERROR)
        else:
            self.fe_time = 0.0
            self.following_error = False
        if j.temperature > OVER_TEMPERATURE:
            self._fault(od.EMCY_OVER_TEMPERATURE_DRIVE, od.ERR_REG_TEMPERATURE)
        if self.mode == od.MODE_PROFILE_POSITION and self.pp_target is not None:
            self.target_reached = (self.q_ref == self.pp_target and
                                   abs(self.pp_target - j.q_measured) * self._k <= self.param(od.POSITION_WINDOW))
        self._update_od(self._k, self._settings_values[1], q_measured)

    def _steady_end(self, core, dt: float) -> bool:
        """on_sync_end in the compiled core (CSP), for a SYNC that changes no state: no stop
        ends, no following-error timeout, no over temperature. False: nothing changed."""
        j = self.joint
        state = self.state
        flags, state_bits = _END_FLAGS[state]
        if self._ramp_from_actual:
            flags |= 16
        if self.limit_active:
            flags |= 32
        q_measured, q_reported, qd_reported = j.readings()
        settings = self._settings_values
        timeout = settings[7] if settings[7] is not None else self.param(od.FOLLOWING_ERROR_TIMEOUT)
        actual = self._actual_values
        if actual._generation == self.store_generation:
            # the actual values written in the same call (a reset emptied the store: write() below)
            out = core.drive_end_write(dt, flags, self._qs_option, self.v_ref, self.brake_closing,
                                       BRAKE_ENGAGE_TIME - 1e-9, self.q_ref, q_measured, self._fe_window, self.fe_time,
                                       timeout, j.temperature, OVER_TEMPERATURE, WARN_TEMPERATURE, state_bits,
                                       self._k, settings[1], q_reported, qd_reported, j.torque_reported, self.mode,
                                       self.error_code, actual._specs, actual._entries, actual._values,
                                       actual._stored, self._params)
            if out is None:
                return False
            self.brake_closing, engaged, self.fe_time, self.following_error, stop, values = out
            j.brake_engaged = engaged
            if stop < len(values):       # a value the core does not write: Python's loop (and error)
                actual.write_from(values, stop)
            return True
        out = core.drive_end(dt, flags, self._qs_option, self.v_ref, self.brake_closing, BRAKE_ENGAGE_TIME - 1e-9,
                             self.q_ref, q_measured, self._fe_window, self.fe_time, timeout, j.temperature,
                             OVER_TEMPERATURE, WARN_TEMPERATURE, state_bits, self._k, settings[1], q_reported,
                             qd_reported, j.torque_reported)
        if out is None:
            return False
        self.brake_closing, engaged, self.fe_time, self.following_error, sw = out[:5]
        j.brake_engaged = engaged
        self._actual_values.write((sw, self.mode, *out[5:], 1 if engaged else 0, self.error_code))
        return True

    def _stop_and_brake(self, dt: float) -> None:
        """End a finished ramp and time the brake: a controlled stop at rest holds the joint
        until the brake has closed, then leaves operation; power off lets the joint go at once
        and the brake closes BRAKE_ENGAGE_TIME later."""
        at_rest = self.v_ref == 0.0 and not self._ramp_from_actual
        option = self._qs_option
        letting_go = (self.state == FAULT_REACTION_ACTIVE and at_rest) or \
                     (self.state == QUICK_STOP_ACTIVE and at_rest and option in (1, 2, 3, 4))
        if self.state not in ENERGISED or letting_go:
            self.brake_closing += dt
        else:
            self.brake_closing = 0.0
        engaged = self.brake_closing >= BRAKE_ENGAGE_TIME - 1e-9
        if letting_go and engaged:
            self.state = FAULT if self.state == FAULT_REACTION_ACTIVE else SWITCH_ON_DISABLED
        self.joint.brake_engaged = engaged

    def _update_od(self, k: float | None = None, rated: float | None = None, q_measured: float | None = None) -> None:
        """The actual values into the OD; k, rated, q_measured: this SYNC's, if known."""
        if k is None:
            k, rated = self._scale(), self._rated_torque()
        j = self.joint
        if q_measured is None:
            q_measured = j.q_measured
        sw = STATE_BITS[self.state] | SW_REMOTE
        if self.limit_active:
            sw |= SW_INTERNAL_LIMIT
        if self.following_error:
            sw |= SW_FOLLOWING_ERROR
        if j.temperature > WARN_TEMPERATURE:
            sw |= SW_WARNING
        if self.mode == od.MODE_CSP:
            if self.state == OPERATION_ENABLED:
                sw |= SW_OP_MODE_12
            if not self.following_error:
                sw |= SW_TARGET_REACHED if self.state != OPERATION_ENABLED else 0
        else:
            if self.pp_ack:
                sw |= SW_OP_MODE_12
            if self.target_reached:
                sw |= SW_TARGET_REACHED
        core = simcore.core
        if core is not None:
            counts = core.actual_values(k, rated, j.q_reported, self.q_ref, j.qd_reported, j.torque_reported,
                                        q_measured, j.temperature)
            if counts is not None:      # None: a value round() raises on, below
                self._actual_values.write((sw, self.mode, *counts, 1 if j.brake_engaged else 0, self.error_code))
                return
        self._actual_values.write((
            sw, self.mode,
            _i32(round(j.q_reported * k)),     # late by any feedback latency
            _i32(round(self.q_ref * k)),
            _i32(round(j.qd_reported * k)),
            max(-32768, min(32767, round(j.torque_reported / rated * 1000.0))),
            _i32(round((self.q_ref - q_measured) * k)),
            max(-32768, min(32767, round(j.temperature * 10.0))),
            1 if j.brake_engaged else 0,
            self.error_code))

    # ------------------------------------------------------------------ state machine
    def _apply_controlword(self, cw: int) -> None:
        reset_edge = cw & CW_FAULT_RESET and not self.prev_cw & CW_FAULT_RESET
        self.prev_cw = cw
        s = self.state
        if s == FAULT:
            if reset_edge and self.joint.temperature <= OVER_TEMPERATURE:   # transition 15
                self.state = SWITCH_ON_DISABLED
                self.error_code = 0
                self.emcy(od.EMCY_NO_ERROR)
            return
        if s == FAULT_REACTION_ACTIVE or cw & CW_FAULT_RESET:
            return
        cmd = decode_controlword(cw)
        if cmd == Command.QUICK_STOP and s == OPERATION_ENABLED and self.faults.ignore_quick_stop:
            return                                      # fault injection: a drive that does not stop
        option = self._qs_option           # this SYNC's (on_sync_begin, _settings)
        new = next_state(s, cmd, option)
        if new == QUICK_STOP_ACTIVE and s == OPERATION_ENABLED:     # 11: 605Ah's ramp
            self._start_ramp(quick=option not in (1, 5))
        if new == OPERATION_ENABLED and s != OPERATION_ENABLED:
            if s != QUICK_STOP_ACTIVE:
                self.q_ref = self.joint.q_measured
            self.v_ref = 0.0
            self.pp_target = None
            self.target_reached = True
            self.fe_time = 0.0
        self.state = new

    def _fault(self, code: int, register_bits: int = 0, emcy: bool = True) -> None:
        if self.state in (FAULT, FAULT_REACTION_ACTIVE):
            if code != self.error_code:           # a further, different error while in fault
                self.error_code = code
                self.put(od.ERROR_CODE, 0, code)
                if emcy:
                    self.emcy(code, od.ERR_REG_PROFILE | register_bits)
            return
        self.error_code = code
        reaction = self.param(od.FAULT_REACTION_OPTION) if od.FAULT_REACTION_OPTION in self.od else 2
        if self.state in (OPERATION_ENABLED, QUICK_STOP_ACTIVE) and reaction != 0:
            self.state = FAULT_REACTION_ACTIVE                              # 13
            self._start_ramp(quick=reaction == 2)
        else:
            self.state = FAULT                                              # 13 + 14
        self.put(od.ERROR_CODE, 0, code)
        if emcy:
            self.emcy(code, od.ERR_REG_PROFILE | register_bits)


def servo_torque(joint, q_ref: float, v_ref: float, q_meas: float, qd: float) -> float:
    """The drive's position servo law (PD scaled by the joint's inertia): motor torque, N m.

    Shared with the direct simulation path (spacearm.offline.diagnosis.direct_sim) so the fast
    replay and the CAN path run the same law."""
    p = joint.params
    w = 2.0 * math.pi * p.servo_bandwidth_hz
    tau_joint = joint.effective_inertia * (w * w * (q_ref - q_meas) + 2.0 * p.servo_damping * w * (v_ref - qd))
    return tau_joint / p.gear_ratio


def _i32(value: int) -> int:
    return max(-2**31, min(2**31 - 1, value))
