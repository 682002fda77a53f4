"""One trial of each calibration study as plain numbers: what a campaign row holds and the study
tables (studies.py) pool.

A trial is one seeded Monte-Carlo run of one study: the laser-ranger paper's (study_laser), the
EKF paper's (study_ekf) or the synthetic study of one measurement model (study_models). It
returns figures (one float each), series (lists: per-axis table entries, per-posture errors for
box plots) and wall-clock timings. Names are the contract with studies.py, kept here in one place.
The campaign runner (offline/campaign) wraps these as trial kinds; this module knows nothing of it.
"""
from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass, field

import numpy as np

from spacearm.controller.calibration import study_ekf as E
from spacearm.controller.calibration import study_laser as L
from spacearm.controller.calibration import study_models as M

LASER_COLUMNS = ("rms_pos", "rms_rot", "max_pos", "max_rot")        # laser paper Table 5, per axis
EKF_TABLE4 = ("pos_mean", "pos_max", "rotx_mean", "rotx_max", "roty_mean", "roty_max", "rotz_mean", "rotz_max")
EKF_METHODS = ("lse", "ekf", "ekf_default", "ekf_cov", "lm")


@dataclass
class TrialNumbers:
    figures: dict[str, float] = field(default_factory=dict)
    series: dict[str, list[float]] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)


def _norm(v) -> float:
    return float(np.linalg.norm(v))


def laser_block(case: int | str, method: str = "") -> str:
    """Series prefix of one validation block: 'nominal', or '<configurations>_<method>'."""
    return str(case) if not method else f"{case}_{method}"


@functools.lru_cache(maxsize=1)
def _laser_setup() -> L.LaserSetup:
    return L.setup()


@functools.lru_cache(maxsize=1)
def _ekf_setup() -> E.EKFSetup:
    return E.setup()


@functools.lru_cache(maxsize=4)
def _model_setup(model: str) -> M.Setup:
    return M.setup(model)


@functools.lru_cache(maxsize=2)
def _shared_validation(seed: int, count: int) -> np.ndarray:
    """Figure 8 validates every trial on the same postures, drawn from their own seed."""
    return E.nonsingular_configurations(_ekf_setup(), count, np.random.default_rng(seed))


def laser_trial(seed: int, noise: float = 0.2e-3, cases=(50,), methods=("lm",), candidates: int = 101,
                validation: int = 20, repetitions: int = 10) -> TrialNumbers:
    """One run of the laser-ranger study: O3-optimal postures per case, each method's fit, Table 5
    quantities per axis as series; the headline figures are the first case's first method."""
    nominal, runs = L.run_once(_laser_setup(), seed, cases=tuple(cases), n_candidates=candidates,
                               n_validation=validation, noise=noise, repetitions=repetitions, methods=tuple(methods))
    out = TrialNumbers()
    out.series.update({f"{laser_block('nominal')}_{c}": nominal.table5()[c].tolist() for c in LASER_COLUMNS})
    out.series["O3"] = [float(r.O3) for r in runs]
    for r in runs:
        for meth, stats in r.stats.items():
            out.series.update({f"{laser_block(r.m, meth)}_{c}": stats.table5()[c].tolist() for c in LASER_COLUMNS})
            out.timings[f"{laser_block(r.m, meth)}_fit_time"] = float(r.fits[meth].elapsed)
    first = runs[0].stats[methods[0]]
    out.figures = {"position_rms_before": _norm(nominal.rms_pos), "position_rms_after": _norm(first.rms_pos),
                   "rotation_rms_after": _norm(first.rms_rot), "O3": float(runs[0].O3), "noise": float(noise)}
    return out


def ekf_trial(seed: int, sigma_p: float = 0.3e-3, sigma_r: float = 0.5 * E.DEG, configurations: int = 50,
              validation: int = 200, methods=("ekf_cov",), validation_seed: int = -1,
              per_posture: bool = False) -> TrialNumbers:
    """One run of the EKF study: Table 4 entries per method (and the nominal 'initial' and the true
    parameters' 'floor') as series; per-posture errors too when asked (box plots). With
    validation_seed >= 0 every trial validates on the same postures (Figure 8)."""
    Qv = _shared_validation(validation_seed, validation) if validation_seed >= 0 else None
    run = E.run_once(_ekf_setup(), seed, n_ident=configurations, n_valid=validation, sigma_p=sigma_p,
                     sigma_r=sigma_r, methods=tuple(methods), Qv=Qv)
    out = TrialNumbers()
    for key, stats in run.stats.items():
        table4 = stats.table4()
        out.series[f"{key}_table4"] = [table4[c] for c in EKF_TABLE4]
        if per_posture:
            out.series[f"{key}_pos_norm"] = stats.pos_norm.tolist()
            for i, ax in enumerate("xyz"):
                out.series[f"{key}_rot_{ax}"] = np.abs(stats.rot[:, i]).tolist()
    out.timings = {f"{m}_fit_time": float(run.fits[m].elapsed) for m in methods}
    first = run.stats[methods[0]]
    out.figures = {"position_rms_before": _norm(run.stats["initial"].rms_pos),
                   "position_rms_after": _norm(first.rms_pos), "rotation_rms_after": _norm(first.rms_rot),
                   "sigma_position": float(sigma_p), "sigma_rotation": float(sigma_r)}
    return out


def model_trial(model: str, seed: int, postures: int = 60, validation: int = 200,
                noise_scale: float = 1.0) -> TrialNumbers:
    """One run of the synthetic study of one measurement model (pose, point, range, plane): the fit's
    validation error against the truth and its Cramer-Rao floor, both in m."""
    st = _model_setup(model)
    if noise_scale != 1.0:
        st = dataclasses.replace(st, sigma=(np.asarray(st.sigma, float) * noise_scale).tolist())
    run = M.run_once(st, postures, seed, n_valid=validation)
    out = TrialNumbers()
    out.figures = {"error": run.error, "floor": run.floor, "error_to_floor": run.error / run.floor,
                   "plausible": float(run.report.verdict.ok), "noise_scale": float(noise_scale)}
    out.timings = {"fit_time": float(run.report.elapsed)}
    return out
