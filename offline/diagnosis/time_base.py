"""Put a recording on a uniform time base, and say what was done to it.

Real loggers repeat rows (the same state read twice), jitter (a host clock), drop samples
and sometimes step back in time. The diagnosis replays the commands one period at a time,
so it needs one period: repeats and rows going back in time are dropped, gaps are bridged
by linear interpolation, and every such step is reported (`--dry-run` prints the report).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

JITTER_TOLERANCE = 0.01      # relative deviation of a step from the median still called uniform
GAP_FACTOR = 1.5             # a step longer than this many periods is a dropped sample
SNAP = 0.25                  # time stamps within this many periods of the cycle grid: rows are cycles


@dataclass
class TimeBaseReport:
    rows_in: int
    rows_out: int
    period: float
    repeats_dropped: int = 0
    backwards_dropped: int = 0
    gaps: int = 0
    longest_gap: float = 0.0
    resampled: bool = False
    filled_values: int = 0        # missing values (empty/NaN) bridged by interpolation
    snapped: bool = False         # rows kept as cycles on the grid (jittery stamps of a clocked loop)
    jitter: float = 0.0           # largest distance of a stamp from its cycle, s

    def lines(self) -> list[str]:
        out = [f"time base: {self.rows_in} rows in, {self.rows_out} rows out, period {1e3 * self.period:.4g} ms"]
        if self.repeats_dropped:
            out.append(f"  dropped {self.repeats_dropped} rows that repeat the previous row exactly")
        if self.backwards_dropped:
            out.append(f"  dropped {self.backwards_dropped} rows whose time stamp does not increase")
        if self.gaps:
            out.append(f"  {self.gaps} gaps longer than {GAP_FACTOR} sampling periods (longest {1e3 * self.longest_gap:.4g} ms),"
                       " bridged by linear interpolation")
        if self.snapped:
            out.append(f"  time stamps jitter up to {1e3 * self.jitter:.3g} ms around a {1e3 * self.period:.4g} ms "
                       "cycle: rows kept as cycles on the grid, missing cycles interpolated")
        elif self.resampled:
            out.append("  time stamps not uniform: resampled onto a uniform grid (linear interpolation)")
        if self.filled_values:
            out.append(f"  {self.filled_values} missing values bridged by linear interpolation")
        return out


def sync_time_base(t: np.ndarray, sync: np.ndarray, counter_max: int) -> np.ndarray | None:
    """Time stamps one SYNC period apart when the recording's SYNC counter (CiA 301, wrapping
    at `counter_max`) advances by one on every row: the simulated plant steps once per SYNC,
    so cycles the controller skipped (gaps in t) took no plant time. None otherwise."""
    if len(t) < 3 or not np.all(np.isfinite(sync)) or not np.all(np.isfinite(t)):
        return None
    step = np.mod(np.diff(sync), counter_max)
    if not np.all(step == 1):
        return None
    period = float(np.min(np.diff(t)))
    if not period > 0:
        return None
    return t[0] + period * np.arange(len(t))


def _is_uniform(steps: np.ndarray) -> bool:
    median = float(np.median(steps))
    return bool(np.all(np.abs(steps - median) <= JITTER_TOLERANCE * median))


def _cycle_numbers(t: np.ndarray, dt: float) -> tuple[np.ndarray, float] | None:
    """(each row's cycle number, the period) if every time stamp is within SNAP periods of a
    whole number of periods from the first (and no two rows share one), else None. The period
    is the span over the whole number of cycles in it (the median step of jittery stamps is
    a little off, and the error adds up over a long recording)."""
    cycles = round(float(t[-1] - t[0]) / dt)
    if cycles < 1:
        return None
    period = float(t[-1] - t[0]) / cycles
    k = (t - t[0]) / period
    n = np.round(k)
    if np.max(np.abs(k - n)) > SNAP or np.any(np.diff(n) < 1):
        return None
    return n, period


def _fill(x: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, int]:
    bad = ~np.isfinite(x)
    if not bad.any():
        return x, 0
    out = x.copy()
    out[bad] = np.interp(t[bad], t[~bad], x[~bad])
    return out, int(bad.sum())


def uniform(t: np.ndarray, columns: dict[str, np.ndarray], period: float | None = None
            ) -> tuple[np.ndarray, dict[str, np.ndarray], TimeBaseReport]:
    """Columns (each (N,) or (N, k)) on a uniform grid from t[0]. `period` forces the grid
    (downsampling averages over each new period first, so no aliasing). Raises ValueError
    with a one-line reason when there is no usable time base."""
    rows_in = len(t)
    keep = np.isfinite(t)
    if keep.sum() < 2:
        raise ValueError("fewer than 2 finite time stamps")
    stacked = np.column_stack([v.reshape(len(t), -1) for v in columns.values()]) if columns else np.zeros((len(t), 0))
    t, stacked = t[keep], stacked[keep]
    report = TimeBaseReport(rows_in, 0, 0.0)
    # time going back or standing still: keep the rows after the running maximum only
    forward = np.ones(len(t), bool)
    forward[1:] = t[1:] > np.maximum.accumulate(t)[:-1]
    report.backwards_dropped = int((~forward).sum())
    t, stacked = t[forward], stacked[forward]
    if len(t) < 2:
        raise ValueError("fewer than 2 rows with increasing time stamps")
    t_end = float(t[-1])
    raw_steps = np.diff(t)
    raw_median = float(np.median(raw_steps))
    report.gaps = int(np.sum(raw_steps > GAP_FACTOR * raw_median))
    report.longest_gap = float(raw_steps.max())
    if not _is_uniform(raw_steps):
        # a jittery logger that re-reads the same state: the repeat carries a wrong time stamp
        same = np.zeros(len(t), bool)
        if stacked.shape[1]:
            same[1:] = np.all((stacked[1:] == stacked[:-1]) | (np.isnan(stacked[1:]) & np.isnan(stacked[:-1])), axis=1)
        if (~same).sum() >= max(10, len(t) // 2):    # else the signals rest: the repeats are the data
            report.repeats_dropped = int(same.sum())
            t, stacked = t[~same], stacked[~same]
    for c in range(stacked.shape[1]):
        if not np.isfinite(stacked[:, c]).any():
            continue                    # an all-empty column stays NaN: the caller names it
        stacked[:, c], filled = _fill(stacked[:, c], t)
        report.filled_values += filled
    steps = np.diff(t)
    median = float(np.median(steps))
    if not np.isfinite(median) or median <= 0:
        raise ValueError("time stamps do not advance")
    dt = float(period) if period else raw_median
    if (t_end - t[0]) / dt > 10 * rows_in + 1_000_000:
        raise ValueError(f"time stamps span {t_end - t[0]:.3g} s, {(t_end - t[0]) / dt:.3g} periods of {dt:.3g} s "
                         f"for {rows_in} rows (a wrong time unit or a time stamp far off?)")
    cycles = None if period else _cycle_numbers(t, dt)
    if _is_uniform(steps) and not period:
        grid, out = t, stacked
    elif cycles is not None:
        # one row per cycle of a clock-driven loop, stamped by a jittery host clock: the rows
        # stay what they are, on the grid; only cycles that are missing get interpolated
        snapped, dt = cycles
        report.snapped = True
        report.jitter = float(np.max(np.abs((t - t[0]) / dt - snapped)) * dt)
        grid = t[0] + dt * np.arange(int(snapped[-1]) + 1)
        out = np.column_stack([np.interp(np.arange(len(grid)), snapped, c) for c in stacked.T]) \
            if stacked.shape[1] else np.zeros((len(grid), 0))
    else:
        report.resampled = True
        grid = t[0] + dt * np.arange(int(np.floor((t_end - t[0]) / dt + 1e-9)) + 1)
        if len(grid) < 2:
            raise ValueError(f"recording shorter than two periods of {dt:g} s")
        src = stacked
        factor = int(round(dt / median))
        if factor > 1:
            # average over one new period before sampling it: a cheap anti-alias filter
            kernel = np.ones(factor) / factor
            src = np.column_stack([np.convolve(np.pad(c, (factor // 2, factor - 1 - factor // 2), mode="edge"),
                                               kernel, mode="valid") for c in stacked.T]) if stacked.shape[1] else src
        out = np.column_stack([np.interp(grid, t, c) for c in src.T]) if src.shape[1] else np.zeros((len(grid), 0))
    report.rows_out, report.period = len(grid), dt
    result, c = {}, 0
    for name, v in columns.items():
        width = 1 if v.ndim == 1 else v.shape[1]
        block = out[:, c:c + width]
        result[name] = block[:, 0] if v.ndim == 1 else block
        c += width
    return grid, result, report
