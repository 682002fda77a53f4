"""`spacearm campaign`: randomised trial campaigns on Dask distributed (offline/campaign).

    spacearm campaign run insertion --results runs/campaigns/insertion [--workers 2 | --scheduler tcp://H:P]
    spacearm campaign run configs/campaigns/insertion.toml --resume --results ...
    spacearm campaign report RESULTS
    spacearm campaign replay RESULTS TRIAL_ID
"""
from __future__ import annotations

import json
import re
import sys
from dataclasses import asdict
from pathlib import Path

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.table import Table

from spacearm.base.paths import CONFIGS
from spacearm.console.errors import EXIT_USAGE, CommandFailed, friendly_errors
from spacearm.offline.campaign.figure_units import figure_unit
from spacearm.offline.campaign.replay import replay as replay_trial
from spacearm.offline.campaign.report import summarise, write_report
from spacearm.offline.campaign.runner import RunSummary, run_campaign
from spacearm.offline.campaign.schema import Campaign, load_campaign
from spacearm.offline.campaign.store import ResultStore, StoreError

SCHEDULER = re.compile(r"^tcp://[^\s/:]+:\d{1,5}$|^tcp://\[[0-9a-fA-F:]+\]:\d{1,5}$")


def _campaign_path(name_or_file: str) -> Path:
    """A file, or the name of one in configs/campaigns/."""
    path = Path(name_or_file)
    if path.suffix == ".toml" or path.exists():
        return path
    return CONFIGS / "campaigns" / f"{name_or_file}.toml"


def register(app: typer.Typer) -> None:
    camp = typer.Typer(help="Randomised trial campaigns on Dask (Monte Carlo insertions, calibration "
                            "studies, soak): resumable, one Parquet file per finished trial.",
                       no_args_is_help=True)

    @camp.command("run")
    @friendly_errors
    def run(campaign: str = typer.Argument(..., help="Campaign file, or a name in configs/campaigns/."),
            results: Path = typer.Option(None, help="Result directory (default runs/campaigns/NAME)."),
            scheduler: str = typer.Option(None, help="tcp://HOST:PORT of a running Dask scheduler "
                                                     "(default: an embedded LocalCluster)."),
            workers: int = typer.Option(None, min=1, max=256, help="LocalCluster worker processes "
                                                                   "(default: one per core)."),
            resume: bool = typer.Option(False, help="Continue a campaign in RESULTS: skip finished trials."),
            limit: int = typer.Option(None, min=1, help="Run at most this many unfinished trials."),
            report: bool = typer.Option(True, help="Write RESULTS/report/ at the end."),
            as_json: bool = typer.Option(False, "--json", help="Print the run summary as JSON.")) -> None:
        """Run (or resume) a campaign; progress on stderr, a summary table at the end."""
        check_scheduler(scheduler)
        spec = load_campaign(_campaign_path(campaign))
        results = results or Path("runs/campaigns") / spec.name
        summary = run_with_progress(spec, results, scheduler, workers, resume, limit, quiet=as_json)
        store = ResultStore(summary.results)
        report_path = write_report(store) if report else None
        if as_json:
            data = {k: str(v) if isinstance(v, Path) else v for k, v in asdict(summary).items()}
            print(json.dumps({**data, "report": str(report_path) if report_path else None}))
            return
        _print_summary(store)
        print(f"{summary.ran} trials in {summary.wall_time:.1f} s on {summary.workers} workers "
              f"({summary.scheduler}); {summary.skipped} done before; results: {summary.results}"
              + (f"; report: {report_path}" if report_path else ""))

    @camp.command("report")
    @friendly_errors
    def report_cmd(results: Path = typer.Argument(..., help="Result directory of a campaign.")) -> None:
        """Summary table, plots (PNG) and report.md of a result directory."""
        store = ResultStore(results)
        try:
            store.manifest()          # a result directory, or one clear line
            store.merge()
            path = write_report(store)
        except StoreError as exc:
            raise CommandFailed(str(exc)) from None
        _print_summary(store)
        print(f"report: {path}")

    @camp.command("replay")
    @friendly_errors
    def replay_cmd(results: Path = typer.Argument(..., help="Result directory of a campaign."),
                   trial: str = typer.Argument(..., help="Trial id (e.g. t000012)."),
                   as_json: bool = typer.Option(False, "--json")) -> None:
        """Re-run one trial alone from its stored seed and compare every figure; exit 1 if they differ."""
        try:
            r = replay_trial(results, trial)
        except StoreError as exc:
            raise CommandFailed(str(exc)) from None
        if as_json:
            print(json.dumps({"trial": r.trial_id, "seed": r.seed, "matches": r.matches,
                              "parameters_equal": r.parameters_equal, "stored_version": r.stored_version,
                              "replay_version": r.replay_version,
                              "figures": {f.name: [f.stored, f.replayed] for f in r.figures},
                              "differing": r.differing}))
        else:
            table = Table(title=f"replay {r.trial_id} (seed {r.seed})")
            for col in ("figure", "unit", "stored", "replayed", "equal"):
                table.add_column(col)
            table.add_row("success", "", str(r.success_stored), str(r.success_replayed),
                          str(r.success_stored == r.success_replayed))
            for f in r.figures:
                unit, factor = figure_unit(f.name)
                table.add_row(f.name, unit, f"{f.stored * factor:.9g}", f"{f.replayed * factor:.9g}", str(f.equal))
            Console().print(table)
            note = "" if r.stored_version == r.replay_version else \
                f" (stored by {r.stored_version}, replayed with {r.replay_version})"
            if r.differing:
                print(f"series/labels that differ: {', '.join(r.differing)}")
            print(("replay matches" if r.matches else "replay DIFFERS") + note)
        if not r.matches:
            raise SystemExit(1)

    app.add_typer(camp, name="campaign")


def check_scheduler(scheduler: str | None) -> None:
    """A usage error (exit 2, one line) unless None or tcp://HOST:PORT."""
    if scheduler is not None and not SCHEDULER.match(scheduler):
        print(f"error: --scheduler: expected tcp://HOST:PORT, got {scheduler!r}", file=sys.stderr)
        raise SystemExit(EXIT_USAGE)


def run_with_progress(spec: Campaign, results: Path, scheduler: str | None = None, workers: int | None = None,
                      resume: bool = False, limit: int | None = None, quiet: bool = False) -> RunSummary:
    """run_campaign with a progress bar on stderr (trials done, failed, broken, ETA); a result
    directory that cannot be used or an unreachable scheduler is one line (CommandFailed)."""
    err = Console(stderr=True)
    columns = (TextColumn(f"{spec.name}"), BarColumn(), MofNCompleteColumn(),
               TextColumn("failed {task.fields[failed]}, broken {task.fields[errors]}"),
               TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn())
    try:
        ResultStore(results).open_for(spec, resume)    # refuse a wrong directory before any output
        with Progress(*columns, console=err, disable=quiet) as progress:
            bar = progress.add_task("trials", total=spec.spec.campaign.trials, failed=0, errors=0)

            def on_progress(done: int, failed: int, errors: int, total: int) -> None:
                progress.update(bar, completed=done, failed=failed, errors=errors)

            return run_campaign(spec, results, scheduler, workers, resume, limit, on_progress)
    except StoreError as exc:
        raise CommandFailed(str(exc)) from None
    except OSError as exc:    # scheduler unreachable (distributed raises OSError on a timeout)
        raise CommandFailed(f"Dask scheduler {scheduler or 'LocalCluster'}: {exc}") from None


def _print_summary(store: ResultStore) -> None:
    s = summarise(store)
    table = Table(title=f"campaign {s.name} ({s.kind}), code {s.code_version}")
    for col in ("figure", "unit", "n", "median", "p95", "max"):
        table.add_column(col)
    rate, _, interval = s.rate_text().partition(" (")
    table.add_row("success rate", "%", str(s.finished - s.errors), rate.removesuffix(" %"), interval.rstrip(")"),
                  f"{s.failed} failed, {s.errors} broken")
    for f in s.figures:
        unit, factor = figure_unit(f.name)     # stored in SI; shown in mm, deg, N, s
        table.add_row(f.name, unit, str(f.count), f"{f.median * factor:.4g}", f"{f.p95 * factor:.4g}",
                      f"{f.maximum * factor:.4g}")
    Console().print(table)
