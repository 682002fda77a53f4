"""Per-cycle timing statistics with warn/error thresholds, as ros2_control reports them.

Percentiles come from a fixed-size window of recent cycles, so memory stays constant over
arbitrarily long runs; totals (count, maxima, overruns) cover the whole run.

Execution time is wake-up to RPDOs written, so it includes waiting for this SYNC's TPDOs
(the bus and the nodes' answer time); compute time is execution minus that wait: what the
controller itself spends. The execution thresholds judge compute time: the wait is bounded by
its own budget and judged where the nodes are (node_timing.py); a simulator that takes 4 ms of
its 8 ms budget to answer is on time, not a slow controller.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import asdict, dataclass, field

import numpy as np


@dataclass(frozen=True)
class CycleThresholds:
    period_error_warn: float = 0.001     # s
    period_error_error: float = 0.005    # s
    execution_warn: float = 0.003        # s of compute (execution less the TPDO wait)
    execution_error: float = 0.010       # s of compute


@dataclass(frozen=True)
class CycleSummary:
    cycles: int
    overruns: int
    skipped_cycles: int
    period_error_median: float
    period_error_p99: float
    period_error_max: float
    execution_median: float
    execution_p99: float
    execution_max: float
    compute_median: float
    compute_p99: float
    warnings: int
    errors: int
    level: str            # "ok" | "warn" | "error": worst threshold crossed in the window
    overrun_causes: dict = field(default_factory=dict)   # judged overruns by cause (overrun_cause.py)

    def as_dict(self) -> dict:
        return asdict(self)


class CycleStats:
    def __init__(self, thresholds: CycleThresholds = CycleThresholds(), window: int = 3000):
        self.thresholds = thresholds
        # rows: period error, execution, compute; one partition finds all medians and p99s
        self._window = np.zeros((3, window))
        self._filled = 0
        self._next = 0
        self.cycles = 0
        self.overruns = 0
        self.skipped_cycles = 0
        self.period_error_max = 0.0
        self.execution_max = 0.0
        self.warnings = 0
        self.errors = 0
        self.overrun_causes: Counter = Counter()     # the daemon's OverrunMeter fills it

    def add(self, period_error: float, execution: float, skipped: int = 0, io_wait: float = 0.0) -> str:
        """Record one cycle (`io_wait`: the part of `execution` spent waiting for TPDOs);
        returns its level ("ok", "warn" or "error")."""
        period_error = abs(period_error)
        window = self._window
        window[0, self._next] = period_error
        window[1, self._next] = execution
        compute = execution - io_wait
        window[2, self._next] = compute
        self._next = (self._next + 1) % window.shape[1]
        self._filled = min(self._filled + 1, window.shape[1])
        self.cycles += 1
        if skipped:
            self.overruns += 1
            self.skipped_cycles += skipped
        self.period_error_max = max(self.period_error_max, period_error)
        self.execution_max = max(self.execution_max, execution)
        t = self.thresholds
        if period_error > t.period_error_error or compute > t.execution_error or skipped:
            self.errors += 1
            return "error"
        if period_error > t.period_error_warn or compute > t.execution_warn:
            self.warnings += 1
            return "warn"
        return "ok"

    def summary(self) -> CycleSummary:
        (pe50, ex50, co50), (pe99, ex99, co99) = median_and_p99(self._window[:, :max(1, self._filled)])
        t = self.thresholds
        if pe99 > t.period_error_error or co99 > t.execution_error:
            level = "error"
        elif pe99 > t.period_error_warn or co99 > t.execution_warn:
            level = "warn"
        else:
            level = "ok"
        return CycleSummary(
            cycles=self.cycles, overruns=self.overruns, skipped_cycles=self.skipped_cycles,
            period_error_median=pe50, period_error_p99=pe99,
            period_error_max=self.period_error_max,
            execution_median=ex50, execution_p99=ex99,
            execution_max=self.execution_max,
            compute_median=co50, compute_p99=co99,
            warnings=self.warnings, errors=self.errors, level=level,
            overrun_causes=dict(self.overrun_causes.most_common()))


def median_and_p99(rows: np.ndarray) -> tuple[list[float], list[float]]:
    """Each row's np.median and np.percentile(row, 99) (linear), to the last bit, from one
    partition: six numpy calls cost ~0.7 ms, once a second of a recorded lockstep run ~1 % of
    its cycle (issue 35)."""
    n = rows.shape[1]
    half = n // 2
    virtual = (n - 1) * 0.99              # numpy's 'linear' virtual index, as it computes it
    low = int(np.floor(virtual))
    high = min(low + 1, n - 1)
    gamma = virtual - low
    below = half - 1 if n % 2 == 0 else half          # the median's lower middle (itself if n is odd)
    ordered = np.partition(rows, sorted({below, half, low, high}), axis=1)
    medians, p99s = [], []
    for m0, m1, a, b in ordered[:, [below, half, low, high]].tolist():
        medians.append(m1 if n % 2 else (m0 + m1) / 2)
        # numpy's _lerp: from the nearer end, so the result stays within [a, b]
        p99s.append(b - (b - a) * (1 - gamma) if gamma >= 0.5 else a + (b - a) * gamma)
    return medians, p99s
