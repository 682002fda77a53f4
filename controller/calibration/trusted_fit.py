"""A calibration fit you can trust: held-out split or k-fold, identifiability on the data's own
postures, residual-scaled uncertainties, optional priors, and a plausibility verdict.

    report = fit_blocks(em, blocks, FitOptions(method="lm", holdout=0.2))
    if not report.verdict.ok: raise SystemExit(report.verdict.message())

Steps: split every block's postures into training and held-out sets (seeded); on the training
postures find the identifiable parameters (rank, condition, reasons for drops); fit them with
the chosen solver (priors only where stated); scale the covariance by the residual (Birge
ratio) unless the noise model is declared exact; evaluate per held-out posture the position
error before (start values) and after; judge plausibility.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from spacearm.controller.calibration.composite import Block, CompositeProblem
from spacearm.controller.calibration.errormodel import ErrorModel
from spacearm.controller.calibration.fit_checks import (Bounds, Priors, Verdict, WeakDirection, data_identifiability,
                                                        instrument_bounds, plausibility, weakest_direction)
from spacearm.controller.calibration.group_selection import GroupSelection, select_groups
from spacearm.controller.calibration.instrument_start import estimate_starts
from spacearm.controller.calibration.identifiability import IdentifiabilityReport
from spacearm.controller.calibration.solvers import CalibrationResult, EKFTuning, ekf, expected_sigma, lm, lse

Array = NDArray[np.float64]
METHODS = ("lm", "lse", "ekf", "ekf-paper")
# Regularisation by default where the kept parameters are weakly conditioned on the data (smallest
# / largest singular value of the unit-scaled Jacobian below WEAK_RATIO): a prior of the size arm
# errors have on the D-H terms only, so the set-up's unknowns stay free.
WEAK_RATIO = 1e-3
DEFAULT_PRIORS = Priors(joint_angle=np.radians(0.5), joint_length=5e-3)
EXTRAPOLATION_MARGIN = 0.01      # rad or m beyond the training range before a posture extrapolates


class FitInputError(ValueError):
    """Options or data that cannot make a fit (unknown method, too few postures): the operator's
    input, not a fit that failed."""


@dataclass(frozen=True)
class FitOptions:
    method: str = "lm"
    holdout: float = 0.2             # fraction of each block's postures held out (0: none)
    kfold: int = 0                   # >1: k-fold cross-validated held-out errors, final fit on all
    seed: int = 0
    priors: Priors = Priors()
    bounds: Bounds = Bounds()
    noise: str = "residual"          # residual: scale covariances by the residual; stated: as given
    max_noise_ratio: float = 3.0     # plausibility: residual RMS / stated noise
    expected_angle: float = np.radians(0.5)   # EKF default prior (expected error size)
    expected_length: float = 2e-3
    worst: int = 5
    starts: bool = True              # anchor / marker / registration start estimated from the data
    regularise: str = "auto"         # auto: DEFAULT_PRIORS on the D-H terms where weakly conditioned; off
    select_groups: bool = False      # drop D-H groups by leave-one-out error on the training postures

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise FitInputError(f"unknown method {self.method!r} ({', '.join(METHODS)})")
        if self.method == "lse" and self.priors.any:
            raise FitInputError("priors (regularisation) need --method lm or ekf; lse is plain least squares")
        if self.regularise not in ("auto", "off"):
            raise FitInputError(f"regularise must be auto or off, not {self.regularise!r}")
        if self.noise not in ("residual", "stated"):
            raise FitInputError(f"noise must be residual or stated, not {self.noise!r}")
        if not (np.isfinite(self.max_noise_ratio) and self.max_noise_ratio > 0):
            raise FitInputError(f"max noise ratio must be positive, not {self.max_noise_ratio!r}")


@dataclass
class HeldOut:
    block: str
    index: int                       # posture row in that block's file
    before: float                    # position error norm with the start values, m
    after: float                     # with the fit, m
    outside: tuple[str, ...] = ()    # joints outside their training range here (extrapolation)
    residual: tuple[float, ...] = ()  # the position error after the fit per reading axis (x, y, z), m


@dataclass
class FitReport:
    result: CalibrationResult
    identifiability: IdentifiabilityReport
    weakest: WeakDirection
    covariance: Array                # of result.free (SI), scaled per FitOptions.noise
    noise_ratio: float               # training RMS of whitened residuals (1 = as stated)
    held_out: list[HeldOut] = field(default_factory=list)
    held_noise_ratio: float | None = None
    verdict: Verdict = field(default_factory=lambda: Verdict(True))
    train_postures: int = 0
    train_position_rms: float = 0.0  # m, RMS position error norm on the training postures
    elapsed: float = 0.0
    priors: Priors = Priors()        # the priors the fit used (DEFAULT_PRIORS when regularised by default)
    regularised: bool = False        # the default priors were applied (weakly conditioned)
    held_unregularised: float | None = None   # held-out RMS of the same fit without them, m
    validation_file: bool = False    # held-out postures are a separate file (another day)
    selection: GroupSelection | None = None   # the final fit's D-H group selection (select_groups)

    def held_rms_where(self, extrapolated: bool) -> tuple[int, float | None]:
        """Count and RMS (after the fit) of held-out postures outside (True) / inside the training range."""
        hs = [h for h in self.held_out if bool(h.outside) == extrapolated]
        return len(hs), (float(np.sqrt(np.mean([h.after ** 2 for h in hs]))) if hs else None)

    def held_rms(self, which: str) -> float | None:
        if not self.held_out:
            return None
        return float(np.sqrt(np.mean([getattr(h, which) ** 2 for h in self.held_out])))

    def held_axis_rms(self) -> Array | None:
        """RMS of the held-out position error per reading axis (x, y, z for points), m."""
        if not self.held_out or len({len(h.residual) for h in self.held_out}) != 1:
            return None
        return np.sqrt(np.mean(np.square([h.residual for h in self.held_out]), axis=0))

    def worst_held_out(self, count: int = 5) -> list[HeldOut]:
        return sorted(self.held_out, key=lambda h: -h.after)[:count]

    @property
    def estimate(self) -> dict[str, float]:
        return self.result.estimate

    @property
    def std(self) -> dict[str, float]:
        """1-sigma uncertainty per estimated parameter (SI)."""
        return {n: float(np.sqrt(max(self.covariance[k, k], 0.0))) for k, n in enumerate(self.result.free)}


def split_rows(n: int, fraction: float, rng: np.random.Generator) -> tuple[Array, Array]:
    perm = rng.permutation(n)
    k = int(round(fraction * n))
    return np.sort(perm[k:]), np.sort(perm[:k])


def solve(problem: CompositeProblem, opts: FitOptions, priors: Priors | None = None) -> CalibrationResult:
    """Run the chosen solver on the free parameters of `problem` (priors: default opts.priors)."""
    free = problem.free
    priors = opts.priors if priors is None else priors
    sig = priors.sigmas(free)
    if opts.method == "lm":
        return lm(problem, x_prior=problem.x0, sigma_prior=sig if priors.any else None)
    if opts.method == "lse":
        return lse(problem)
    if opts.method == "ekf":
        prior = np.where(np.isfinite(sig), sig, expected_sigma(free, opts.expected_angle, opts.expected_length))
        tuning = EKFTuning(prior ** 2, np.zeros_like(prior), np.eye(1))
        return ekf(problem, tuning, passes=3)
    if opts.method == "ekf-paper":
        return ekf(problem, EKFTuning.paper(problem), passes=3)
    raise ValueError(f"unknown method {opts.method!r} ({', '.join(METHODS)})")


def _covariance(problem: CompositeProblem, res: CalibrationResult, opts: FitOptions,
                priors: Priors) -> tuple[Array, float]:
    """Covariance of the free parameters from the whitened Jacobian at the estimate, and the noise ratio."""
    r, A = problem.residual_and_jacobian(res.x)
    G = A[:, 0, problem.free_idx]
    rw = r[:, 0]
    ip2 = np.where(np.isfinite(s := priors.sigmas(problem.free)), 1.0 / s ** 2, 0.0)
    cov = np.linalg.pinv(G.T @ G + np.diag(ip2), rcond=1e-12)
    dof = max(len(rw) - len(problem.free), 1)
    ratio = float(np.sqrt(rw @ rw / dof))
    if opts.noise == "residual":
        cov = cov * ratio ** 2           # Birge ratio: the data say how large the noise really is
    return cov, ratio


def _held_out(problem: CompositeProblem, test_blocks: list[Block], rows: list[Array],
              x: Array) -> tuple[list[HeldOut], float]:
    """Per held-out posture position errors before/after (and the joints it has outside the
    training postures' range), and the whitened held-out noise ratio."""
    # Held-out blocks share their instruments with the training blocks (the same model objects),
    # so one problem over both maps every parameter, also where only some instruments are scored.
    n_train = len(problem.blocks)
    hp = CompositeProblem(problem.model, problem.blocks + test_blocks, list(problem.free), problem.x0)
    before = hp.position_errors(hp.x0)[n_train:]
    after = hp.position_errors(x)[n_train:]
    Qt = np.concatenate([b.Q for b in problem.blocks])
    lo, hi = Qt.min(axis=0) - EXTRAPOLATION_MARGIN, Qt.max(axis=0) + EXTRAPOLATION_MARGIN
    joints = problem.model.kin.joint_names
    out = []
    for b, idx, e0, e1 in zip(test_blocks, rows, before, after):
        for k in range(len(idx)):
            off = (b.Q[k] < lo) | (b.Q[k] > hi)
            out.append(HeldOut(b.label, int(idx[k]), float(np.linalg.norm(e0[k])), float(np.linalg.norm(e1[k])),
                               tuple(str(joints[j]) if j < len(joints) else f"q{j + 1}" for j in np.flatnonzero(off)),
                               tuple(float(v) for v in e1[k])))
    rw = [np.matmul(W, r[:, :, None]).reshape(-1)
          for (r, _), W in zip(hp.block_residuals(x, jacobian=False)[n_train:], hp._W[n_train:])]
    return out, float(np.sqrt(np.mean(np.concatenate(rw) ** 2)))


def _rms_norm(errors: list[Array]) -> float:
    return float(np.sqrt(np.mean(np.concatenate([np.sum(e ** 2, axis=1) for e in errors]))))


def fit_blocks(em: ErrorModel, blocks: list[Block], opts: FitOptions = FitOptions(),
               candidates: list[str] | None = None, x0: Array | None = None,
               validation: list[Block] | None = None) -> FitReport:
    """Identify, fit, validate and judge. `candidates` default: every D-H parameter, the
    registration and tool frames and every instrument parameter (the identifiable ones are kept).
    `validation`: readings of another session (same instruments, any postures); the fit then uses
    every posture of `blocks` and is scored on these instead of a held-out split."""
    t0 = time.perf_counter()
    if opts.starts and x0 is None:
        blocks = estimate_starts(em, blocks, candidates)
    if validation:
        validation = [_same_instrument(v, blocks) for v in validation]
    full = CompositeProblem(em, blocks, [], x0)
    cands = list(full.names) if candidates is None else list(candidates)
    bounds = instrument_bounds(full, opts.bounds)
    rng = np.random.default_rng(opts.seed)
    if validation:
        final_train = [np.arange(len(b.Q)) for b in blocks]
        train_sets, test_sets, test_blocks = [final_train], [None], [validation]
    elif opts.kfold > 1:
        folds = [np.array_split(rng.permutation(len(b.Q)), opts.kfold) for b in blocks]
        train_sets = [[np.setdiff1d(np.arange(len(b.Q)), f[i]) for b, f in zip(blocks, folds)]
                      for i in range(opts.kfold)]
        test_sets = [[np.sort(f[i]) for f in folds] for i in range(opts.kfold)]
        final_train = [np.arange(len(b.Q)) for b in blocks]
        test_blocks = [[b.subset(t) for b, t in zip(blocks, te)] for te in test_sets]
    else:
        splits = [split_rows(len(b.Q), opts.holdout, rng) for b in blocks]
        train_sets, test_sets = [[s[0] for s in splits]], [[s[1] for s in splits]]
        final_train = train_sets[0]
        test_blocks = [[b.subset(t) for b, t in zip(blocks, test_sets[0])]]

    selections: dict[int, GroupSelection] = {}

    def fit_on(rows: list[Array], priors: Priors | None = None):
        tp = CompositeProblem(em, [b.subset(r) for b, r in zip(blocks, rows)], [], full.x0)
        n_rows = sum(len(r) * b.model.rows for b, r in zip(blocks, rows))
        use = cands
        if opts.select_groups:
            selections[id(rows)] = _select(em, tp.blocks, opts, cands, full.x0)
            use = selections[id(rows)].kept
        rep = data_identifiability(tp.with_free(use), use, bounds=bounds)
        if n_rows < len(rep.kept) + 1:
            raise FitInputError(f"{n_rows} equations for {len(rep.kept)} identifiable parameters: measure more postures")
        tp = tp.with_free(rep.kept)
        if priors is None:
            priors = opts.priors
            if opts.regularise == "auto" and not priors.any and opts.method != "lse" and rep.kept \
                    and weakest_direction(tp, rep.kept).sigma_ratio < WEAK_RATIO:
                priors = DEFAULT_PRIORS
        return tp, rep, solve(tp, opts, priors), priors

    held: list[HeldOut] = []
    held_ratios = []
    final = None
    for tr, te, tb in zip(train_sets, test_sets, test_blocks):
        if not any(len(b.Q) for b in tb):
            continue
        fitted = fit_on(tr)
        if tr is final_train:
            final = fitted
        rows = te if te is not None else [np.arange(len(b.Q)) for b in tb]
        h, ratio = _held_out(fitted[0], tb, rows, fitted[2].x)
        held += h
        held_ratios.append(ratio)
    tp, rep, res, priors = final if final is not None else fit_on(final_train)
    cov, ratio = _covariance(tp, res, opts, priors)
    report = FitReport(res, rep, weakest_direction(tp, rep.kept), cov, ratio, held,
                       float(np.sqrt(np.mean(np.square(held_ratios)))) if held_ratios else None,
                       train_postures=sum(len(r) for r in final_train),
                       train_position_rms=_rms_norm(tp.position_errors(res.x)),
                       priors=priors, regularised=priors is DEFAULT_PRIORS, validation_file=bool(validation),
                       selection=selections.get(id(final_train)))
    if report.regularised and held and opts.kfold <= 1:
        # The effect of the default priors on the held-out error, reported beside the fit.
        tp_u, _, res_u, _ = fit_on(final_train, Priors())
        rows = test_sets[0] if test_sets[0] is not None else [np.arange(len(b.Q)) for b in test_blocks[0]]
        report.held_unregularised = _rms_of(_held_out(tp_u, test_blocks[0], rows, res_u.x)[0])
    corr = res.x[tp.free_idx] - tp.x0[tp.free_idx]
    report.verdict = plausibility(res.status, res.message, tp.free, corr, bounds, ratio,
                                  report.held_noise_ratio, report.held_rms("before"), report.held_rms("after"),
                                  opts.max_noise_ratio)
    report.elapsed = time.perf_counter() - t0
    return report


def _select(em: ErrorModel, train: list[Block], opts: FitOptions, cands: list[str], x0: Array) -> GroupSelection:
    """D-H groups kept by leave-one-posture-out error on these training blocks only (nested: the
    caller's held-out or validation postures are not among them)."""
    inner = dataclasses.replace(opts, select_groups=False, kfold=0, holdout=0.0, starts=False)

    def cv_error(names: list[str]) -> float:
        try:
            rep = fit_blocks(em, train, inner, candidates=names, x0=x0)
        except FitInputError:           # fewer equations than parameters
            return float("inf")
        return loo_position_rms(CompositeProblem(em, train, rep.result.free, x0), rep.result.x, rep.priors)
    return select_groups(cands, cv_error)


def loo_position_rms(problem: CompositeProblem, x: Array, priors: Priors) -> float:
    """RMS over (block, posture) of the position error each posture would have were it left out
    of the fit (m): the fit linearised at `x`, e_i = (I - H_ii)^-1 r_i with H the whitened hat
    matrix (priors included), then un-whitened. Exact for a linear model; one fit instead of one
    per posture, so no fold draw decides a close call."""
    r, A = problem.residual_and_jacobian(x)
    r, A = r[:, 0], A[:, 0, problem.free_idx]
    sig = priors.sigmas(problem.free) if priors.any else np.full(len(problem.free), np.inf)
    M = A.T @ A + np.diag(1.0 / np.square(sig))
    try:
        G = A @ np.linalg.pinv(M, rcond=1e-12, hermitian=True)
    except np.linalg.LinAlgError:
        return float("inf")
    sq, row = [], 0
    for b in problem.blocks:
        k = b.model.rows
        W = b.whitening()
        for i in range(len(b.Q)):
            g = slice(row + i * k, row + (i + 1) * k)
            H = G[g] @ A[g].T
            try:
                e = np.linalg.solve(W[i], np.linalg.solve(np.eye(k) - H, r[g]))
            except np.linalg.LinAlgError:   # this posture alone determines a parameter
                return float("inf")
            sq.append(float(np.sum(e[:3] ** 2)))
        row += len(b.Q) * k
    return float(np.sqrt(np.mean(sq)))


def _rms_of(held: list[HeldOut]) -> float | None:
    return float(np.sqrt(np.mean([h.after ** 2 for h in held]))) if held else None


def _same_instrument(v: Block, blocks: list[Block]) -> Block:
    """A validation block measured with the training block's instrument of the same kind and
    label stem (so it shares that instrument's estimated start and fitted parameters)."""
    for b in blocks:
        if type(b.model) is type(v.model) and b.model.extra_names == v.model.extra_names:
            return dataclasses.replace(v, model=b.model)
    return v
