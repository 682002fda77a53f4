"""The result directory of a campaign: nothing finished is ever lost.

    RESULTS/campaign.json         code version (git describe), campaign file hash and text, created
    RESULTS/trials/t000012.parquet one file per finished trial, written atomically as it completes
    RESULTS/results.parquet        the merged view (rebuilt from trials/ at the end and on `report`)

A crash loses at most the trials that were running; `resume` lists trials/ and skips those.
Every row names the code version, the campaign hash and the trial's seed, so any trial can be
replayed alone. pandas/pyarrow open either the merged file or the trials/ directory directly.
"""
from __future__ import annotations

import json
import os
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from spacearm.base.paths import REPO_ROOT
from spacearm.offline.campaign.schema import Campaign, campaign_from_text

MANIFEST = "campaign.json"
TRIALS = "trials"
MERGED = "results.parquet"


class StoreError(Exception):
    """The result directory cannot be used as asked (the message says why)."""


def code_version() -> str:
    """`git describe --always --dirty` of the clone, or the package version outside a clone."""
    try:
        out = subprocess.run(["git", "-C", str(REPO_ROOT), "describe", "--always", "--dirty", "--tags"],
                             capture_output=True, text=True, timeout=10)
        if out.returncode == 0 and out.stdout.strip():
            return out.stdout.strip()
    except (OSError, subprocess.SubprocessError):
        pass
    from importlib.metadata import version
    return f"spacearm-{version('spacearm')}"


@dataclass
class TrialRecord:
    """One row of the result table."""
    trial_id: str
    index: int
    seed: int
    success: bool
    failure: str | None
    error: str | None              # the trial raised (after its retries): no figures
    parameters: dict[str, float]
    figures: dict[str, float]
    timings: dict[str, float]
    worker: str
    code_version: str
    campaign_hash: str
    finished_at: float
    series: dict[str, list[float]] = field(default_factory=dict)   # per-trial arrays (e.g. per posture)
    labels: dict[str, str] = field(default_factory=dict)           # words a table groups by

    def row(self) -> dict[str, Any]:
        row: dict[str, Any] = {"trial_id": self.trial_id, "index": self.index, "seed": self.seed,
                               "success": self.success, "failure": self.failure, "error": self.error}
        row.update({f"p_{k}": float(v) for k, v in self.parameters.items()})
        row.update({f"f_{k}": float(v) for k, v in self.figures.items()})
        row.update({f"w_{k}": float(v) for k, v in self.timings.items()})
        row.update({f"s_{k}": [float(x) for x in v] for k, v in self.series.items()})
        row.update({f"l_{k}": str(v) for k, v in self.labels.items()})
        row.update({"worker": self.worker, "code_version": self.code_version,
                    "campaign_hash": self.campaign_hash, "finished_at": self.finished_at})
        return row


class ResultStore:
    def __init__(self, root: str | Path):
        self.root = Path(root)
        self.trials_dir = self.root / TRIALS
        self._meta: dict[bytes, bytes] | None = None

    def _metadata(self) -> dict[bytes, bytes]:
        """Parquet key-value metadata: each file names its campaign on its own (file, text, hash).
        Read once: the campaign of a directory never changes (open_for refuses another)."""
        if self._meta is None:
            m = self.manifest()
            self._meta = {b"spacearm.campaign_file": m.get("campaign_file", "").encode(),
                          b"spacearm.campaign_hash": m["campaign_hash"].encode(),
                          b"spacearm.campaign_text": m["campaign_text"].encode()}
        return self._meta

    # --- opening -----------------------------------------------------------------------------
    def open_for(self, campaign: Campaign, resume: bool) -> dict[str, Any]:
        """Create the directory for `campaign`, or (resume) check it holds this same campaign."""
        manifest_path = self.root / MANIFEST
        if manifest_path.exists():
            manifest = self.manifest()
            if manifest["campaign_hash"] != campaign.file_hash:
                raise StoreError(f"{self.root}: holds campaign {manifest['name']!r} "
                                 f"(hash {manifest['campaign_hash']}), not this file (hash {campaign.file_hash}); "
                                 "use another --results directory")
            if not resume and self.done_ids():
                raise StoreError(f"{self.root}: already has {len(self.done_ids())} finished trials; "
                                 "pass --resume to continue, or use another --results directory")
            # a trial half-written when the last run was killed: never renamed, so never counted
            for stale in self.trials_dir.glob(".*.tmp"):
                stale.unlink(missing_ok=True)
            if manifest["code_version"] != code_version():
                manifest.setdefault("resumed_with", []).append(code_version())
                self._write_json(manifest_path, manifest)
            return manifest
        self.trials_dir.mkdir(parents=True, exist_ok=True)
        manifest = {"name": campaign.name, "kind": campaign.kind, "code_version": code_version(),
                    "campaign_hash": campaign.file_hash, "campaign_file": campaign.path,
                    "campaign_text": campaign.text, "seed": campaign.spec.campaign.seed,
                    "trials": campaign.spec.campaign.trials, "created": time.time()}
        self._write_json(manifest_path, manifest)
        return manifest

    def manifest(self) -> dict[str, Any]:
        path = self.root / MANIFEST
        if not path.exists():
            raise StoreError(f"{self.root}: not a campaign result directory (no {MANIFEST})")
        try:
            return json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise StoreError(f"{path}: unreadable ({exc})") from None

    def campaign(self) -> Campaign:
        m = self.manifest()
        return campaign_from_text(m["campaign_text"], m.get("campaign_file", "<stored campaign>"))

    # --- trials --------------------------------------------------------------------------------
    def done_ids(self) -> set[str]:
        if not self.trials_dir.is_dir():
            return set()
        return {p.stem for p in self.trials_dir.glob("t*.parquet")}

    def write(self, record: TrialRecord) -> Path:
        """Atomic: a reader (or a resume after a crash) sees the whole file or none of it."""
        path = self.trials_dir / f"{record.trial_id}.parquet"
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        table = pa.Table.from_pylist([record.row()])
        pq.write_table(table.replace_schema_metadata(self._metadata()), tmp)
        os.replace(tmp, path)
        return path

    def table(self) -> pa.Table:
        files = sorted(self.trials_dir.glob("t*.parquet")) if self.trials_dir.is_dir() else []
        if not files:
            return pa.table({"trial_id": pa.array([], pa.string())})
        tables = [pq.read_table(f) for f in files]
        return pa.concat_tables(tables, promote_options="default").sort_by("index")

    def merge(self) -> Path:
        path = self.root / MERGED
        tmp = path.with_name(f".{MERGED}.tmp")
        pq.write_table(self.table().replace_schema_metadata(self._metadata()), tmp)
        os.replace(tmp, path)
        return path

    def rows(self) -> list[dict[str, Any]]:
        return self.table().to_pylist()

    def outcomes(self) -> dict[str, tuple]:
        """trial id -> (seed, success, parameters and figures): what equal seeds must reproduce
        (no timings, workers or dates), for comparing two runs of a campaign."""
        return {r["trial_id"]: (r["seed"], r["success"],
                                {k: v for k, v in r.items() if k[:2] in ("p_", "f_", "s_", "l_")})
                for r in self.rows()}

    def row(self, trial_id: str) -> dict[str, Any]:
        path = self.trials_dir / f"{trial_id}.parquet"
        if not path.exists():
            raise StoreError(f"{self.root}: no finished trial {trial_id!r}")
        return pq.read_table(path).to_pylist()[0]

    @staticmethod
    def _write_json(path: Path, data: dict) -> None:
        tmp = path.with_name(f".{path.name}.tmp")
        tmp.write_text(json.dumps(data, indent=2))
        os.replace(tmp, path)
