"""Per-cycle timing statistics with warn/error thresholds, as ros2_control reports them.

Percentiles come from a fixed-size window of recent cycles, so memory stays constant over
arbitrarily long runs; totals (count, maxima, overruns) cover the whole run.

Execution time is wake-up to RPDOs written, so it includes waiting for this SYNC's TPDOs
(the bus and the nodes' answer time); compute time is execution minus that wait: what the
controller itself spends.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class CycleThresholds:
    period_error_warn: float = 0.001     # s
    period_error_error: float = 0.005    # s
    execution_warn: float = 0.003        # s
    execution_error: float = 0.010       # s


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

    def as_dict(self) -> dict:
        return asdict(self)


class CycleStats:
    def __init__(self, thresholds: CycleThresholds = CycleThresholds(), window: int = 3000):
        self.thresholds = thresholds
        self._period_error = np.zeros(window)
        self._execution = np.zeros(window)
        self._compute = np.zeros(window)
        self._filled = 0
        self._next = 0
        self.cycles = 0
        self.overruns = 0
        self.skipped_cycles = 0
        self.period_error_max = 0.0
        self.execution_max = 0.0
        self.warnings = 0
        self.errors = 0

    def add(self, period_error: float, execution: float, skipped: int = 0, io_wait: float = 0.0) -> str:
        """Record one cycle (`io_wait`: the part of `execution` spent waiting for TPDOs);
        returns its level ("ok", "warn" or "error")."""
        period_error = abs(period_error)
        self._period_error[self._next] = period_error
        self._execution[self._next] = execution
        self._compute[self._next] = execution - io_wait
        self._next = (self._next + 1) % len(self._period_error)
        self._filled = min(self._filled + 1, len(self._period_error))
        self.cycles += 1
        if skipped:
            self.overruns += 1
            self.skipped_cycles += skipped
        self.period_error_max = max(self.period_error_max, period_error)
        self.execution_max = max(self.execution_max, execution)
        t = self.thresholds
        if period_error > t.period_error_error or execution > t.execution_error or skipped:
            self.errors += 1
            return "error"
        if period_error > t.period_error_warn or execution > t.execution_warn:
            self.warnings += 1
            return "warn"
        return "ok"

    def summary(self) -> CycleSummary:
        pe = self._period_error[: self._filled]
        ex = self._execution[: self._filled]
        co = self._compute[: self._filled]
        if self._filled == 0:
            pe = ex = co = np.zeros(1)
        t = self.thresholds
        pe99, ex99 = float(np.percentile(pe, 99)), float(np.percentile(ex, 99))
        if pe99 > t.period_error_error or ex99 > t.execution_error:
            level = "error"
        elif pe99 > t.period_error_warn or ex99 > t.execution_warn:
            level = "warn"
        else:
            level = "ok"
        return CycleSummary(
            cycles=self.cycles, overruns=self.overruns, skipped_cycles=self.skipped_cycles,
            period_error_median=float(np.median(pe)), period_error_p99=pe99,
            period_error_max=self.period_error_max,
            execution_median=float(np.median(ex)), execution_p99=ex99,
            execution_max=self.execution_max,
            compute_median=float(np.median(co)), compute_p99=float(np.percentile(co, 99)),
            warnings=self.warnings, errors=self.errors, level=level)
