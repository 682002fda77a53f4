"""`spacearm calibrate study WHICH`: a calibration study as campaigns on the Dask runner.

Each Monte-Carlo run of the study is one trial (offline/campaign/kind_calibration.py) of a
campaign written here from the command's options; the trials run on a LocalCluster (or
--scheduler), each finished one lands in RESULTS/trials/*.parquet, a second call resumes the
unfinished ones, and the papers' tables are pooled from the rows (controller/calibration/studies).
Under --json only the headline numbers go to stdout; tables and progress go to stderr.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import typer

from spacearm.console.commands.campaign import check_scheduler, run_with_progress
from spacearm.console.errors import CommandFailed, friendly_errors
from spacearm.controller.calibration import studies as S
from spacearm.controller.calibration.study_ekf import NOISE_LEVELS
from spacearm.offline.campaign.schema import campaign_from_text, campaign_text
from spacearm.offline.campaign.store import ResultStore

STUDIES = ("laser-ranger", "ekf", *S.MODELS)
DEFAULT_RUNS = {"laser-ranger": 20, "ekf": 10}        # the measurement models: 20

def _rows(text: str, results: Path, scheduler: str | None, workers: int | None, resume: bool) -> list[dict]:
    """Run (or resume) one campaign; the rows of its finished trials. A broken trial stops the study."""
    campaign = campaign_from_text(text, f"calibrate study ({results})")
    run_with_progress(campaign, results, scheduler, workers, resume)      # the bar goes to stderr
    rows = ResultStore(results).rows()
    broken = [r["trial_id"] for r in rows if r["error"]]
    if broken:
        raise CommandFailed(f"{len(broken)} trials raised ({', '.join(broken[:5])}): see {results}/trials; "
                            "the tables need every trial")
    return rows


def _unique(values) -> list[float]:
    return sorted(set(values))


def run_study(which: str, runs: int, seed: int, out: Path | None, results: Path, scheduler: str | None,
              workers: int | None, resume: bool, postures: int = 60) -> tuple[str, dict]:
    if which == "laser-ranger":
        text = campaign_text("study_laser_ranger", "calibration_laser", seed, runs,
                             options={"configurations": list(S.LASER_CASES), "methods": ["lm", "lse"]})
        return S.laser_tables(_rows(text, results, scheduler, workers, resume), seed, S.LASER_CASES)
    if which == "ekf":
        # the paper's four noise levels are the cross of two position and two rotation sigmas
        noise = campaign_text("study_ekf_noise_levels", "calibration_ekf", seed, len(NOISE_LEVELS) * runs,
                              levels={"sigma_position": _unique(sp for sp, _ in NOISE_LEVELS),
                                      "sigma_rotation": _unique(sr for _, sr in NOISE_LEVELS)},
                              options={"methods": list(S.EKF_METHODS), "per_posture": out is not None})
        counts = campaign_text("study_ekf_configurations", "calibration_ekf", seed, len(S.EKF_COUNTS) * runs,
                               levels={"configurations": list(S.EKF_COUNTS)},
                               options={"methods": list(S.EKF_CURVES),
                                        "validation_seed": S.FIG8_VALIDATION_SEED + seed})
        noise_rows = _rows(noise, results / "noise_levels", scheduler, workers, resume)
        count_rows = _rows(counts, results / "configurations", scheduler, workers, resume)
        return S.ekf_tables(noise_rows, count_rows, out)
    text = campaign_text(f"study_{which}", "calibration_model", seed, runs,
                         options={"model": which, "postures": postures})
    return S.model_tables(which, _rows(text, results, scheduler, workers, resume))


def register_study(cal: typer.Typer) -> None:
    @cal.command("study")
    @friendly_errors
    def study(which: str = typer.Argument(..., help=" | ".join(STUDIES)),
              runs: int = typer.Option(0, min=0, max=100_000,
                                       help="Monte-Carlo runs (default 20 laser and models, 10 ekf per level)."),
              seed: int = typer.Option(0, min=0, max=2 ** 32 - 1, help="Campaign seed."),
              postures: int = typer.Option(60, min=10, max=5000, help="Measurement models: postures per fit."),
              out: Path = typer.Option(Path("calibration_plots"), help="Folder for PNG plots (ekf)."),
              results: Path = typer.Option(None, help="Result directory (default runs/calibration_studies/"
                                                      "WHICH-seedS-runsN[-posturesP])."),
              resume: bool = typer.Option(True, help="Reuse the finished trials in RESULTS (--no-resume: "
                                                     "refuse a directory that has some)."),
              scheduler: str = typer.Option(None, help="tcp://HOST:PORT of a running Dask scheduler "
                                                       "(default: an embedded LocalCluster)."),
              workers: int = typer.Option(None, min=1, max=256, help="LocalCluster workers (default: one per core)."),
              as_json: bool = typer.Option(False, "--json", help="Only the headline numbers on stdout, as JSON.")
              ) -> None:
        """Reproduce a paper's simulation study (or one measurement model's) on the campaign runner
        and print our tables beside the paper's."""
        if which not in STUDIES:
            raise CommandFailed(f"unknown study {which!r}; choose one of {', '.join(STUDIES)}")
        check_scheduler(scheduler)
        runs = runs or DEFAULT_RUNS.get(which, 20)
        model_size = f"-postures{postures}" if which in S.MODELS else ""
        results = results or Path("runs/calibration_studies") / f"{which}-seed{seed}-runs{runs}{model_size}"
        text, head = run_study(which, runs, seed, out if which == "ekf" else None, results, scheduler, workers,
                               resume, postures)
        head["results"] = str(results)
        print(text, file=sys.stderr if as_json else sys.stdout)
        if as_json:
            print(json.dumps(head, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))
        else:
            print(f"trials and their Parquet rows: {results}")
