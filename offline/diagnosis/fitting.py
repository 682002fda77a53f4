"""Fit candidate effects to one channel's residual; choose by held-out error and BIC.

Residual samples are correlated (servo dynamics, resolver chatter), so the significance test
counts blocks, not rows: the block length is where the fitted model's residual stops being
correlated, and the chi-square statistic of the error reduction is divided by it.

Standard errors: the larger of the block-scaled least-squares one and a delete-a-block
jackknife over contiguous stretches of the training rows. The jackknife holds when the
residual is correlated over seconds and when the law does not quite fit (the estimate then
moves with the stretch of recording it sees); with few blocks it is scaled by the t quantile
so that 1.96 standard errors is a 95 % interval, which is how the report states it.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy import stats
from scipy.optimize import minimize_scalar

from spacearm.offline.diagnosis.candidates import Candidate, Signals

POSITIVE = ("coulomb_friction", "viscous_friction", "stribeck_friction")
SIGNIFICANCE = 1e-6          # per test; about 80 tests per recording
MIN_HELDOUT_REDUCTION = 0.10
JACKKNIFE_BLOCKS = 8         # contiguous stretches of the training rows (3 s each on a 40 s recording)
Z95 = 1.96


@dataclass
class ChannelFit:
    effects: tuple[str, ...]
    channel: str
    index: int                   # joint (0-based) or F/T axis
    coef: np.ndarray
    stderr: np.ndarray
    columns: tuple[str, ...]
    shape: tuple[float, ...]     # grid values chosen (one per effect, nan = none)
    sse_train: float
    sse_null_train: float
    rms_heldout_before: float
    rms_heldout_after: float
    p_value: float
    block: int
    prediction: np.ndarray = field(repr=False, default=None)   # over all rows
    n_train: int = 0
    n_params: int = 0
    judged_by: str = "samples"   # or "envelope", "breakaway": how its held-out figures were made
    # the coefficients' correlation (least squares, from the design): None = taken as independent.
    # A size that is a function of several coefficients (a load's amplitude from its cos and sin
    # parts) needs it: over a short stroke those two trade off, their own errors are large, and
    # the amplitude's can still be small
    correlation: np.ndarray | None = field(repr=False, default=None)

    def bic_at(self, block: int) -> float:
        """BIC with a given block length. Candidates on one channel must be compared at one
        common block length: with each fit's own, a worse fit (longer correlated residual,
        fewer effective samples) gets the lower BIC whenever the mean square error exceeds 1."""
        if not np.isfinite(self.sse_train) or self.n_train == 0:
            return np.inf
        n_eff = max(self.n_train / block, self.n_params + 2.0)
        return float(n_eff * np.log(max(self.sse_train, 1e-30) / self.n_train) + self.n_params * np.log(n_eff))

    @property
    def heldout_reduction(self) -> float:
        if self.rms_heldout_before <= 0:
            return 0.0
        return 1.0 - self.rms_heldout_after / self.rms_heldout_before

    @property
    def significant(self) -> bool:
        return self.p_value < SIGNIFICANCE and self.heldout_reduction >= MIN_HELDOUT_REDUCTION

    @property
    def by_envelope(self) -> bool:
        """Judged on a statistic of the residual, not sample by sample: its RMS envelope (gear
        effects, whose ripple has no reproducible phase) or its breakaway peaks (stick-slip)."""
        if self.judged_by == "samples":
            return self.effects[0] in ("backlash", "elasticity")
        return self.judged_by != "stiff gear"     # a stiff gear is judged sample by sample (stiff_gear)


def correlation_length(x: np.ndarray, cap: int = 100) -> int:
    """Lag where the autocorrelation first falls below 0.2 (at least 1)."""
    x = x - x.mean()
    var = float(x @ x)
    if var <= 0:
        return 1
    for lag in range(1, min(cap, len(x) // 4)):
        if float(x[:-lag] @ x[lag:]) / var < 0.2:
            return lag
    return cap


def _lstsq(X: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float]:
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ coef
    return coef, float(r @ r)


def fit_features(effects: tuple[str, ...], channel: str, index: int, columns: tuple[str, ...],
                 shape: tuple[float, ...], X: np.ndarray, y: np.ndarray, train: np.ndarray,
                 fixed_gain: bool = False, held: np.ndarray | None = None,
                 estimate: Callable[[np.ndarray], np.ndarray | None] | None = None) -> ChannelFit:
    """Fit on the `train` rows; judge on `held` (default: all other rows). `estimate(rows)`
    refits the coefficients on a subset of rows (for the jackknife); default: least squares
    on X with the shape held."""
    held = ~train if held is None else held
    if fixed_gain:
        coef = np.ones(X.shape[1])
        sse = float(np.sum((y[train] - X[train] @ coef) ** 2))
        gain, _ = _lstsq(X[train], y[train])
        if not 0.5 < gain[0] < 1.5:          # the shape must explain the residual at its own size
            sse = np.inf
    else:
        scale = np.sqrt(np.mean(X[train] ** 2, axis=0))
        whole = np.sqrt(np.mean(X ** 2, axis=0))     # a shape the held-out rows excite but these do not
        if np.any(scale < 1e-6 * np.maximum(max(float(scale.max()), 1e-300), whole)) or np.any(scale == 0.0):
            # the recording never excites this shape: a least-squares coefficient would be noise
            coef, sse = np.zeros(X.shape[1]), np.inf
        elif _one_shape(X[train] / scale):
            # two effects of one shape on these rows (a constant force and Coulomb friction on a
            # one-way motion): how the fit splits it between them would be arbitrary
            coef, sse = np.zeros(X.shape[1]), np.inf
        else:
            coef, sse = _lstsq(X[train], y[train])
        if any(c < 0.0 for c, name in zip(coef, columns) if name in POSITIVE):
            sse = np.inf                     # friction that pushes the joint along is not friction
    pred = X @ coef
    n = int(train.sum())
    sse0 = float(y[train] @ y[train])
    resid = y[train] - pred[train]
    block = correlation_length(resid)
    sigma2 = max(sse / n, 1e-30)
    k = X.shape[1] + sum(1 for s in shape if not np.isnan(s))
    chi = max(sse0 - sse, 0.0) / sigma2 / block if np.isfinite(sse) else 0.0
    p = float(stats.chi2.sf(chi, k))
    correlation = None
    try:
        cov = sigma2 * block * np.linalg.inv(X[train].T @ X[train])
        stderr = np.sqrt(np.clip(np.diag(cov), 0, None))
        if np.all(np.isfinite(stderr) & (stderr > 0)):
            correlation = cov / np.outer(stderr, stderr)
    except np.linalg.LinAlgError:
        stderr = np.full(X.shape[1], np.nan)
    if not fixed_gain and np.isfinite(sse):
        refit = estimate or (lambda rows: _excited_lstsq(X, y, rows))
        stderr = np.maximum(stderr, block_jackknife_stderr(refit, np.flatnonzero(train), len(coef)))
    before = float(np.sqrt(np.mean(y[held] ** 2))) if held.any() else 0.0
    after = float(np.sqrt(np.mean((y[held] - pred[held]) ** 2))) if held.any() else 0.0
    return ChannelFit(effects, channel, index, coef, stderr, columns, shape, sse, sse0, before, after, p,
                      block, pred, n, k, correlation=correlation)


def _one_shape(X: np.ndarray) -> bool:
    """Whether the (scaled) columns are linearly dependent: one shape in two names."""
    if X.shape[1] < 2:
        return False
    sv = np.linalg.svd(X, compute_uv=False)
    return bool(sv[-1] < 1e-9 * sv[0])


def _excited_lstsq(X: np.ndarray, y: np.ndarray, rows: np.ndarray) -> np.ndarray | None:
    """Least squares on `rows`, or None where they leave a column unexcited."""
    if np.any(np.sqrt(np.mean(X[rows] ** 2, axis=0)) < 1e-9 * max(float(np.abs(X).max()), 1.0)):
        return None
    return _lstsq(X[rows], y[rows])[0]


def block_jackknife_stderr(estimate: Callable[[np.ndarray], np.ndarray | None], rows: np.ndarray,
                           n_coef: int, blocks: int = JACKKNIFE_BLOCKS) -> np.ndarray:
    """Delete-a-block jackknife standard errors over contiguous stretches of `rows`, scaled
    by t(0.975, blocks - 1) / 1.96 (few blocks: the spread is itself uncertain). Each
    stretch is much longer than the residual's correlation, which is what makes the
    pseudo-values close to independent. Zero (no evidence either way) where the rows are too
    few or a refit fails."""
    if len(rows) < 20 * blocks:
        return np.zeros(n_coef)
    est = []
    for part in np.array_split(np.arange(len(rows)), blocks):
        keep = np.ones(len(rows), bool)
        keep[part] = False
        coef = estimate(rows[keep])
        if coef is None or not np.all(np.isfinite(coef)):
            return np.zeros(n_coef)
        est.append(coef)
    est = np.array(est)
    var = (blocks - 1) / blocks * np.sum((est - est.mean(axis=0)) ** 2, axis=0)
    return np.sqrt(var) * _t975(blocks - 1) / Z95


@functools.lru_cache(maxsize=None)
def _t975(dof: int) -> float:
    """t(0.975, dof): the same few degrees of freedom every jackknife, and scipy's ppf costs a
    millisecond each time (a tenth of a jackknife)."""
    return float(stats.t.ppf(0.975, dof))


def common_block(fits: list[ChannelFit]) -> int:
    """The block length the best-fitting candidate's residual shows: the scale at which
    all candidates of one channel are compared."""
    finite = [f for f in fits if np.isfinite(f.sse_train)]
    return min(finite, key=lambda f: f.sse_train).block if finite else 1


def fit_candidate(candidate: Candidate, s: Signals, y: np.ndarray, train: np.ndarray, index: int,
                  held: np.ndarray | None = None) -> ChannelFit:
    grid = candidate.grid
    if grid == ("quantiles",):
        grid = tuple(float(np.quantile(np.abs(s.tau), q)) for q in (0.5, 0.7, 0.8, 0.9, 0.95, 0.98))
    best = None
    for value in grid or (np.nan,):
        X = candidate.features(s, value)
        fit = fit_features((candidate.effect,), candidate.channel, index, candidate.columns, (value,), X, y, train,
                           candidate.fixed_gain, held)
        if best is None or fit.sse_train < best.sse_train:
            best = fit
    if candidate.grid and candidate.grid != ("quantiles",) and not candidate.fixed_gain and \
            np.isfinite(best.sse_train):
        best = _profiled(candidate, s, y, train, index, held, best.shape[0])
    return best


def _profile_shape(candidate: Candidate, s: Signals, y: np.ndarray, rows: np.ndarray, start: float
                   ) -> tuple[float, np.ndarray | None]:
    """The shape parameter (and the linear sizes at it) that fits `rows` best, searched on a
    log scale within a factor 1.6 of `start`: the size and the shape (a Stribeck level and
    its decay speed) trade off against each other, so they are fitted together, not the
    size at the nearest grid point."""
    def sse(log_value: float) -> float:
        X = candidate.features(s, math.exp(log_value))[rows]
        if float(np.sqrt(np.mean(X ** 2))) < 1e-9:
            return float(y[rows] @ y[rows])   # a shape the rows never excite explains nothing
        return _lstsq(X, y[rows])[1]
    x0 = math.log(start)
    found = minimize_scalar(sse, bounds=(x0 - 0.47, x0 + 0.47), method="bounded", options={"xatol": 0.005})
    value = float(math.exp(found.x))
    return value, _excited_lstsq(candidate.features(s, value), y, rows)


def _profiled(candidate: Candidate, s: Signals, y: np.ndarray, train: np.ndarray, index: int,
              held: np.ndarray | None, start: float) -> ChannelFit:
    """The candidate at its jointly fitted shape; the jackknife refits the shape too, so the
    stated interval of the size carries the shape's uncertainty."""
    value, _ = _profile_shape(candidate, s, y, np.flatnonzero(train), start)
    return fit_features((candidate.effect,), candidate.channel, index, candidate.columns, (value,),
                        candidate.features(s, value), y, train, held=held,
                        estimate=lambda rows: _profile_shape(candidate, s, y, rows, value)[1])


def fit_pair(a: Candidate, b: Candidate, s: Signals, y: np.ndarray, train: np.ndarray, index: int,
             shape_a: float, shape_b: float, held: np.ndarray | None = None) -> ChannelFit:
    X = np.column_stack([a.features(s, shape_a), b.features(s, shape_b)])
    return fit_features((a.effect, b.effect), a.channel, index, a.columns + b.columns, (shape_a, shape_b), X, y,
                        train, held=held)
