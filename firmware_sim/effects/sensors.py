"""Sensor effects: feedback latency (a delay line of whole SYNC cycles) and F/T sensor errors."""
from __future__ import annotations

from collections import deque
from typing import Sequence


class DelayLine:
    """Returns what was pushed `cycles` pushes ago (the first value until filled)."""

    def __init__(self, cycles: int, initial: float):
        self.cycles = cycles
        self._values: deque[float] = deque([initial] * (cycles + 1), maxlen=cycles + 1)

    def push(self, value: float) -> None:
        self._values.append(value)

    @property
    def output(self) -> float:
        return self._values[0]


def ft_sensor_error(true: Sequence[float], t: float, temperature_delta: float, bias: Sequence[float],
                    drift: Sequence[float], scale_error: Sequence[float],
                    temp_coefficient: Sequence[float]) -> list[float]:
    """Reading of a six-axis F/T sensor without noise: scale error, bias, drift over time
    (per second since power-on) and a temperature coefficient (per K from the reference)."""
    return [w * (1.0 + scale_error[i]) + bias[i] + drift[i] * t + temp_coefficient[i] * temperature_delta
            for i, w in enumerate(true)]
