"""`spacearm calibrate study WHICH`: a calibration study as campaigns on the Dask runner.

Each Monte-Carlo run of the study is one trial (offline/campaign/kind_calibration.py) of a
campaign written from the command's options; the trials run on a LocalCluster (or
--scheduler), each finished one lands in RESULTS/trials/*.parquet, a second call resumes the
unfinished ones, and the papers' tables are pooled from the rows (offline/campaign/calibration_study.py,
shared with bench/bench_calibration.py).
Under --json only the headline numbers go to stdout; tables and progress go to stderr.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import typer

from spacearm.console.commands.campaign import check_scheduler, run_with_progress
from spacearm.console.errors import BadInput, CommandFailed, friendly_errors
from spacearm.controller.calibration.studies import MODELS
from spacearm.offline.campaign.calibration_study import DEFAULT_RUNS, STUDIES, BrokenTrials, run_study


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
            raise BadInput(f"unknown study {which!r}; choose one of {', '.join(STUDIES)}")
        check_scheduler(scheduler)
        runs = runs or DEFAULT_RUNS.get(which, 20)
        model_size = f"-postures{postures}" if which in MODELS else ""
        results = results or Path("runs/calibration_studies") / f"{which}-seed{seed}-runs{runs}{model_size}"
        try:      # the progress bar goes to stderr
            text, head = run_study(which, runs, seed, out if which == "ekf" else None, results,
                                   lambda campaign, where: run_with_progress(campaign, where, scheduler, workers,
                                                                             resume), postures)
        except BrokenTrials as exc:
            raise CommandFailed(str(exc)) from None
        head["results"] = str(results)
        print(text, file=sys.stderr if as_json else sys.stdout)
        if as_json:
            print(json.dumps(head, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))
        else:
            print(f"trials and their Parquet rows: {results}")
