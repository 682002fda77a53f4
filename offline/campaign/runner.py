"""Run a campaign on Dask distributed: one task per trial, results written as they finish.

A LocalCluster (worker processes on this machine, one trial at a time each) by default, or any
running scheduler (`tcp://HOST:PORT`). Dask does the scheduling: a worker that dies has its
trial re-run on another worker (the scheduler's own recovery); a trial that raises is retried
`retries` times, then recorded as an error row. The client writes each finished trial to the
result store at once, so a killed campaign resumes with only the unfinished trials.
"""
from __future__ import annotations

import functools
import os
import socket
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from spacearm.offline.campaign.kinds import KINDS
from spacearm.offline.campaign.schema import Campaign, trial_id
from spacearm.offline.campaign.store import ResultStore, TrialRecord, code_version


@dataclass(frozen=True)
class TrialTask:
    """Everything a worker needs for one trial: plain values, so any worker can run it."""
    kind: str
    index: int
    seed: int
    parameters: dict[str, float]
    options: dict[str, Any]


def execute_trial(task: TrialTask) -> dict[str, Any]:
    """Runs on a worker. Returns plain values; an exception travels back to the client."""
    kind = KINDS[task.kind]
    started = time.perf_counter()
    outcome = kind.run(task.parameters, task.options, task.seed)
    timings = {"task_wall_time": time.perf_counter() - started, **outcome.timings}
    return {"success": bool(outcome.success), "failure": outcome.failure, "figures": dict(outcome.figures),
            "series": {k: [float(x) for x in v] for k, v in outcome.series.items()},
            "labels": {k: str(v) for k, v in outcome.labels.items()}, "timings": timings, "worker": _worker_name(), "code_version": _worker_code_version()}


@functools.lru_cache(maxsize=1)
def _worker_code_version() -> str:
    """The code that ran the trial: the worker's own clone (another host may run another commit)."""
    return code_version()


def _worker_name() -> str:
    """The Dask worker's address (which host or namespace ran the trial), else host:pid."""
    try:
        from distributed import get_worker
        return get_worker().address
    except ValueError:              # not inside a worker (replay runs in this process)
        return f"{socket.gethostname()}:{os.getpid()}"


def make_task(campaign: Campaign, index: int) -> TrialTask:
    return TrialTask(campaign.kind, index, campaign.trial_seed(index), campaign.parameters(index),
                     dict(campaign.spec.options))


@dataclass
class RunSummary:
    total: int
    skipped: int          # finished before this run (resume)
    ran: int              # finished in this run
    failed: int           # finished, not successful (this run)
    errors: int           # raised after all retries (this run)
    wall_time: float      # s, the whole run (cluster start to merged file)
    startup_time: float   # s, client (and LocalCluster) start until workers are there
    trials_time: float    # s, first submit to last result written
    workers: int
    scheduler: str
    results: Path


ProgressHook = Callable[[int, int, int, int], None]   # done, failed, errors, total


def start_client(scheduler: str | None, workers: int | None):
    """(client, cluster or None). An embedded LocalCluster listens on 127.0.0.1 only."""
    from distributed import Client, LocalCluster

    if scheduler:
        return Client(scheduler, timeout="20s"), None
    n = workers or max(1, os.cpu_count() or 1)
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address=None, silence_logs=40)
    return Client(cluster), cluster


def run_campaign(campaign: Campaign, results: str | Path, scheduler: str | None = None,
                 workers: int | None = None, resume: bool = False, limit: int | None = None,
                 on_progress: ProgressHook | None = None) -> RunSummary:
    """Run the campaign's unfinished trials (all of them on a new directory). `limit`: stop
    submitting after this many (for tests and the resume benchmark)."""
    from distributed import as_completed

    store = ResultStore(results)
    manifest = store.open_for(campaign, resume)
    total = campaign.spec.campaign.trials
    done = store.done_ids()
    pending = [i for i in range(total) if trial_id(i) not in done]
    if limit is not None:
        pending = pending[:limit]
    version = code_version()      # this client's, for trials that raised (no worker answer)
    started = time.perf_counter()
    ran = failed = errors = 0
    client, cluster = start_client(scheduler, workers)
    try:
        n_workers = len(client.nthreads())
        startup = time.perf_counter() - started
        tasks = {}
        for i in pending:
            task = make_task(campaign, i)
            # the key names campaign and trial: a second client submitting the same trial shares it
            key = f"trial-{campaign.file_hash}-{trial_id(i)}"
            future = client.submit(execute_trial, task, key=key, pure=False,
                                   retries=campaign.spec.campaign.retries)
            tasks[future.key] = (future, task)
        if on_progress:
            on_progress(len(done), 0, 0, total)
        for future in as_completed([f for f, _ in tasks.values()]):
            task = tasks.pop(future.key)[1]      # drop our reference: the workers free the result
            record = _record(future, task, version, manifest["campaign_hash"])
            store.write(record)
            ran += 1
            failed += int(record.error is None and not record.success)
            errors += int(record.error is not None)
            if on_progress:
                on_progress(len(done) + ran, failed, errors, total)
        trials_time = time.perf_counter() - started - startup
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    store.merge()
    return RunSummary(total, len(done), ran, failed, errors, time.perf_counter() - started, startup, trials_time,
                      n_workers, scheduler or "LocalCluster", store.root)


def _record(future, task: TrialTask, version: str, campaign_hash: str) -> TrialRecord:
    try:
        out = future.result()
        error = None
    except Exception as exc:   # the trial raised on every attempt: record why, keep the campaign going
        out = {"success": False, "failure": None, "figures": {}, "timings": {}, "worker": ""}
        error = f"{type(exc).__name__}: {exc}"
    return TrialRecord(trial_id(task.index), task.index, task.seed, out["success"], out["failure"], error,
                       task.parameters, out["figures"], out["timings"], out["worker"],
                       out.get("code_version", version), campaign_hash, time.time(),
                       out.get("series", {}), out.get("labels", {}))
