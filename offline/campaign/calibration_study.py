"""A calibration study (the laser-ranger or EKF paper's, or one measurement model's) as campaigns
on the Dask runner: the campaign files written from the study's size and seed, the trials run
(or resumed), the papers' tables pooled from the Parquet rows (controller/calibration/studies).

`spacearm calibrate study` (with its progress bar) and bench/bench_calibration.py both call
run_study; each Monte-Carlo run of a study is one trial (offline/campaign/kind_calibration.py).
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

from spacearm.controller.calibration import studies as S
from spacearm.controller.calibration.study_ekf import NOISE_LEVELS
from spacearm.offline.campaign.schema import Campaign, campaign_from_text, campaign_text
from spacearm.offline.campaign.store import ResultStore

STUDIES = ("laser-ranger", "ekf", *S.MODELS)
DEFAULT_RUNS = {"laser-ranger": 20, "ekf": 10}        # the measurement models: 20

# run(campaign, results directory): runs (or resumes) its trials
Runner = Callable[[Campaign, Path], object]


class BrokenTrials(RuntimeError):
    """Trials of a study raised (after their retries): the tables need every trial."""


def campaign_runner(scheduler: str | None = None, workers: int | None = None, resume: bool = True) -> Runner:
    from spacearm.offline.campaign.runner import run_campaign
    return lambda campaign, results: run_campaign(campaign, results, scheduler, workers, resume)


def study_rows(text: str, results: Path, run: Runner) -> list[dict]:
    """Run (or resume) one campaign; the rows of its finished trials. A broken trial stops the study."""
    run(campaign_from_text(text, f"calibration study ({results})"), results)
    rows = ResultStore(results).rows()
    broken = [r["trial_id"] for r in rows if r["error"]]
    if broken:
        raise BrokenTrials(f"{len(broken)} trials raised ({', '.join(broken[:5])}): see {results}/trials; "
                           "the tables need every trial")
    return rows


def _unique(values) -> list[float]:
    return sorted(set(values))


def run_study(which: str, runs: int, seed: int, out: Path | None, results: Path, run: Runner | None = None,
              postures: int = 60, counts=S.EKF_COUNTS) -> tuple[str, dict]:
    """The study's tables and headline numbers. `run` defaults to run_campaign on a LocalCluster
    (resuming); ekf: `runs` per noise level and per configuration count of `counts`."""
    run = run or campaign_runner()
    if which == "laser-ranger":
        text = campaign_text("study_laser_ranger", "calibration_laser", seed, runs,
                             options={"configurations": list(S.LASER_CASES), "methods": ["lm", "lse"]})
        return S.laser_tables(study_rows(text, results, run), seed, S.LASER_CASES)
    if which == "ekf":
        # the paper's four noise levels are the cross of two position and two rotation sigmas
        noise = campaign_text("study_ekf_noise_levels", "calibration_ekf", seed, len(NOISE_LEVELS) * runs,
                              levels={"sigma_position": _unique(sp for sp, _ in NOISE_LEVELS),
                                      "sigma_rotation": _unique(sr for _, sr in NOISE_LEVELS)},
                              options={"methods": list(S.EKF_METHODS), "per_posture": out is not None})
        by_count = campaign_text("study_ekf_configurations", "calibration_ekf", seed, len(counts) * runs,
                                 levels={"configurations": list(counts)},
                                 options={"methods": list(S.EKF_CURVES),
                                          "validation_seed": S.FIG8_VALIDATION_SEED + seed})
        noise_rows = study_rows(noise, results / "noise_levels", run)
        count_rows = study_rows(by_count, results / "configurations", run)
        return S.ekf_tables(noise_rows, count_rows, out)
    if which not in S.MODELS:
        raise ValueError(f"unknown study {which!r}; choose one of {', '.join(STUDIES)}")
    text = campaign_text(f"study_{which}", "calibration_model", seed, runs,
                         options={"model": which, "postures": postures})
    return S.model_tables(which, study_rows(text, results, run))
