"""Simulated six-axis force/torque sensor: samples the plant's wrench at every SYNC.

Fx..Tz (2200h.1..6, INTEGER16) in counts of 2201h (per N) and 2202h (per N m), status
2203h (bit 0 overload, bit 1 tared), tare command 2204h (1 tare, 2 clear bias; an SDO
write always executes, an RPDO executes when the value changes). Overload (any axis
above 2205h limits or saturated) raises an EMCY once per occurrence.
"""
from __future__ import annotations

from spacearm.base.canopen import od
from spacearm.firmware_sim.node import SimNode
from spacearm.firmware_sim.od_cyclic import CyclicObjects


class FtSensorNode(SimNode):
    device_type = "ft_sensor"

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._readings = CyclicObjects(self, [(od.FT_VALUES, i) for i in range(1, 7)] + [(od.FT_STATUS, 0)])

    def reset_application(self) -> None:
        self.bias = [0.0] * 6
        self.tared = False
        self.overload = False
        self.pending_tare: int | None = None
        self.last_rpdo_tare = 0
        self._sample()

    _scaling = (-1, (), ())
    # (reading, its types, bias, scaling, counts, overload, the bias' values): _sample's last
    _last_sample = (None,) * 7

    def _read_scaling(self) -> tuple:
        """(param() cache epoch, counts per unit and overload limit of each axis): param()'s
        values, read again whenever the cache dropped one."""
        kf = self.param(od.FT_FORCE_COUNTS_PER_N)
        kt = self.param(od.FT_TORQUE_COUNTS_PER_NM)
        flim = self.param(od.FT_OVERLOAD_LIMIT, 1)
        tlim = self.param(od.FT_OVERLOAD_LIMIT, 2)
        self._scaling = (self._params.epoch, (kf,) * 3 + (kt,) * 3, (flim,) * 3 + (tlim,) * 3)
        return self._scaling

    WRITE_REACTIONS = frozenset({od.FT_TARE})     # the only object on_write looks at

    def on_write(self, index: int, subindex: int, data: bytes) -> None:
        if index == od.FT_TARE:
            value = data[0] if data else 0
            if self.in_rpdo:
                if value == self.last_rpdo_tare:
                    return
                self.last_rpdo_tare = value
            if value in (1, 2):
                self.pending_tare = value

    def on_sync_end(self, dt: float) -> None:
        if self.faults.frozen:
            return  # fault injection: the last sample goes out again and again
        self._sample()

    def _sample(self) -> None:
        raw = self.plant.ft_reading()
        if self.pending_tare == 1:
            self.bias, self.tared = list(raw), True
        elif self.pending_tare == 2:
            self.bias, self.tared = [0.0] * 6, False
        self.pending_tare = None
        scaling = self._scaling
        if scaling[0] != self._params.epoch:
            scaling = self._read_scaling()
        # The same reading (equal values of the same types), bias and scaling as the last sample
        # (a wrench at rest, nearly every SYNC) give the same counts and overload flag: those are
        # kept rather than worked out again (issue 35); the status and the write are as below.
        types = [value.__class__ for value in raw]
        last = self._last_sample
        if last[0] == raw and last[1] == types and last[2] is self.bias and last[6] == self.bias \
                and last[3] is scaling and last[5] == self.overload:
            values = last[4] + [(od.FT_STATUS_OVERLOAD if self.overload else 0) |
                                (od.FT_STATUS_TARED if self.tared else 0)]
            self._readings.write(values)
            return
        _, scales, limits = scaling
        # per axis as a loop over i would: value = raw - bias, its counts, overload when above
        # the axis' limit or beyond INTEGER16 (saturated); the lists each in one pass
        # (issue 35: the sample was a tenth of the simulator's SYNC)
        errors = [value - bias for value, bias in zip(raw, self.bias)]
        values = [round(value * scale) for value, scale in zip(errors, scales)]
        overload = max(values) > 32767 or min(values) < -32768
        if overload:
            values = [max(-32768, min(32767, counts)) for counts in values]
        elif any(abs(value) > limit for value, limit in zip(errors, limits)):
            overload = True
        if overload and not self.overload:
            self.emcy(od.EMCY_FT_OVERLOAD, od.ERR_REG_MANUFACTURER)
        elif self.overload and not overload:
            self.emcy(od.EMCY_NO_ERROR)
        self.overload = overload
        self._last_sample = (raw, types, self.bias, scaling, values[:], overload, list(self.bias))
        values.append((od.FT_STATUS_OVERLOAD if overload else 0) | (od.FT_STATUS_TARED if self.tared else 0))
        self._readings.write(values)
