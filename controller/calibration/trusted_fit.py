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

import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from spacearm.controller.calibration.composite import Block, CompositeProblem
from spacearm.controller.calibration.errormodel import ErrorModel
from spacearm.controller.calibration.fit_checks import (Bounds, Priors, Verdict, WeakDirection,
                                               data_identifiability, plausibility, weakest_direction)
from spacearm.controller.calibration.identifiability import IdentifiabilityReport
from spacearm.controller.calibration.solvers import CalibrationResult, EKFTuning, ekf, expected_sigma, lm, lse

Array = NDArray[np.float64]
METHODS = ("lm", "lse", "ekf", "ekf-paper")


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

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"unknown method {self.method!r} ({', '.join(METHODS)})")
        if self.method == "lse" and self.priors.any:
            raise ValueError("priors (regularisation) need --method lm or ekf; lse is plain least squares")
        if self.noise not in ("residual", "stated"):
            raise ValueError(f"noise must be residual or stated, not {self.noise!r}")


@dataclass
class HeldOut:
    block: str
    index: int                       # posture row in that block's file
    before: float                    # position error norm with the start values, m
    after: float                     # with the fit, m


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

    def held_rms(self, which: str) -> float | None:
        if not self.held_out:
            return None
        return float(np.sqrt(np.mean([getattr(h, which) ** 2 for h in self.held_out])))

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


def solve(problem: CompositeProblem, opts: FitOptions) -> CalibrationResult:
    """Run the chosen solver on the free parameters of `problem`."""
    free = problem.free
    sig = opts.priors.sigmas(free)
    if opts.method == "lm":
        return lm(problem, x_prior=problem.x0, sigma_prior=sig if opts.priors.any else None)
    if opts.method == "lse":
        return lse(problem)
    if opts.method == "ekf":
        prior = np.where(np.isfinite(sig), sig, expected_sigma(free, opts.expected_angle, opts.expected_length))
        tuning = EKFTuning(prior ** 2, np.zeros_like(prior), np.eye(1))
        return ekf(problem, tuning, passes=3)
    if opts.method == "ekf-paper":
        return ekf(problem, EKFTuning.paper(problem), passes=3)
    raise ValueError(f"unknown method {opts.method!r} ({', '.join(METHODS)})")


def _covariance(problem: CompositeProblem, res: CalibrationResult, opts: FitOptions) -> tuple[Array, float]:
    """Covariance of the free parameters from the whitened Jacobian at the estimate, and the noise ratio."""
    r, A = problem.residual_and_jacobian(res.x)
    G = A[:, 0, problem.free_idx]
    rw = r[:, 0]
    ip2 = np.where(np.isfinite(s := opts.priors.sigmas(problem.free)), 1.0 / s ** 2, 0.0)
    cov = np.linalg.pinv(G.T @ G + np.diag(ip2), rcond=1e-12)
    dof = max(len(rw) - len(problem.free), 1)
    ratio = float(np.sqrt(rw @ rw / dof))
    if opts.noise == "residual":
        cov = cov * ratio ** 2           # Birge ratio: the data say how large the noise really is
    return cov, ratio


def _held_out(problem: CompositeProblem, test_blocks: list[Block], rows: list[Array],
              x: Array) -> tuple[list[HeldOut], float]:
    """Per held-out posture position errors before/after, and the whitened held-out noise ratio."""
    hp = problem.with_blocks(test_blocks)
    before = hp.position_errors(hp.x0)
    after = hp.position_errors(x)
    out = []
    for b, idx, e0, e1 in zip(test_blocks, rows, before, after):
        for k in range(len(idx)):
            out.append(HeldOut(b.label, int(idx[k]), float(np.linalg.norm(e0[k])), float(np.linalg.norm(e1[k]))))
    r, _ = hp.residual_and_jacobian(x)
    return out, float(np.sqrt(np.mean(r ** 2)))


def _rms_norm(errors: list[Array]) -> float:
    return float(np.sqrt(np.mean(np.concatenate([np.sum(e ** 2, axis=1) for e in errors]))))


def fit_blocks(em: ErrorModel, blocks: list[Block], opts: FitOptions = FitOptions(),
               candidates: list[str] | None = None, x0: Array | None = None) -> FitReport:
    """Identify, fit, validate and judge. `candidates` default: every D-H parameter, the
    registration and tool frames and every instrument parameter (the identifiable ones are kept)."""
    t0 = time.perf_counter()
    full = CompositeProblem(em, blocks, [], x0)
    cands = list(full.names) if candidates is None else list(candidates)
    rng = np.random.default_rng(opts.seed)
    if opts.kfold > 1:
        folds = [np.array_split(rng.permutation(len(b.Q)), opts.kfold) for b in blocks]
        train_sets = [[np.setdiff1d(np.arange(len(b.Q)), f[i]) for b, f in zip(blocks, folds)]
                      for i in range(opts.kfold)]
        test_sets = [[np.sort(f[i]) for f in folds] for i in range(opts.kfold)]
        final_train = [np.arange(len(b.Q)) for b in blocks]
    else:
        splits = [split_rows(len(b.Q), opts.holdout, rng) for b in blocks]
        train_sets, test_sets = [[s[0] for s in splits]], [[s[1] for s in splits]]
        final_train = train_sets[0]

    def fit_on(rows: list[Array]) -> tuple[CompositeProblem, IdentifiabilityReport, CalibrationResult]:
        tp = CompositeProblem(em, [b.subset(r) for b, r in zip(blocks, rows)], [], full.x0)
        n_rows = sum(len(r) * b.model.rows for b, r in zip(blocks, rows))
        rep = data_identifiability(tp.with_free(cands), cands)
        if n_rows < len(rep.kept) + 1:
            raise ValueError(f"{n_rows} equations for {len(rep.kept)} identifiable parameters: measure more postures")
        tp = tp.with_free(rep.kept)
        return tp, rep, solve(tp, opts)

    held: list[HeldOut] = []
    held_ratios = []
    for tr, te in zip(train_sets, test_sets):
        if not any(len(t) for t in te):
            continue
        tp, _, res = fit_on(tr)
        h, ratio = _held_out(tp, [b.subset(t) for b, t in zip(blocks, te)], te, res.x)
        held += h
        held_ratios.append(ratio)
    tp, rep, res = fit_on(final_train)
    cov, ratio = _covariance(tp, res, opts)
    report = FitReport(res, rep, weakest_direction(tp, rep.kept), cov, ratio, held,
                       float(np.sqrt(np.mean(np.square(held_ratios)))) if held_ratios else None,
                       train_postures=sum(len(r) for r in final_train),
                       train_position_rms=_rms_norm(tp.position_errors(res.x)))
    corr = res.x[tp.free_idx] - tp.x0[tp.free_idx]
    report.verdict = plausibility(res.status, res.message, tp.free, corr, opts.bounds, ratio,
                                  report.held_noise_ratio, report.held_rms("before"), report.held_rms("after"),
                                  opts.max_noise_ratio)
    report.elapsed = time.perf_counter() - t0
    return report
