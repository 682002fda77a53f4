"""`spacearm calibrate study` on the campaign runner: Parquet rows per trial, resume, JSON-only stdout."""
from __future__ import annotations

import json
import re
import subprocess
import sys

import pytest

from spacearm.base.paths import CONFIGS, REPO_ROOT
from spacearm.offline.campaign.store import ResultStore

pytestmark = pytest.mark.slow

SPACEARM = [sys.executable, "-m", "spacearm.console.main"]


def cli(*args: str, timeout: float = 400) -> subprocess.CompletedProcess:
    return subprocess.run([*SPACEARM, *args], capture_output=True, text=True, timeout=timeout, cwd=REPO_ROOT)


def test_a_measurement_model_study_runs_as_trials_and_resumes(tmp_path):
    results = tmp_path / "point"
    args = ("calibrate", "study", "point", "--runs", "3", "--postures", "40", "--workers", "1",
            "--results", str(results), "--json")
    first = cli(*args)
    assert first.returncode == 0, first.stderr
    head = json.loads(first.stdout)                     # stdout is the JSON alone
    assert head["runs"] == 3 and 0.5 < head["error_to_floor"] < 1.5
    assert "Measurement model 'point'" in first.stderr and "Measurement model" not in first.stdout
    store = ResultStore(results)
    assert sorted(store.done_ids()) == ["t000000", "t000001", "t000002"]
    stamps = {p.name: p.stat().st_mtime_ns for p in (results / "trials").glob("*.parquet")}
    again = cli(*args)                                  # resumes: nothing left to run, same tables
    assert again.returncode == 0, again.stderr
    assert json.loads(again.stdout) == head
    assert {p.name: p.stat().st_mtime_ns for p in (results / "trials").glob("*.parquet")} == stamps


def test_the_ekf_study_prints_the_papers_tables_from_its_trials(tmp_path):
    out = cli("calibrate", "study", "ekf", "--runs", "1", "--results", str(tmp_path / "ekf"),
              "--out", str(tmp_path / "plots"))
    assert out.returncode == 0, out.stderr
    for heading in ("Table 4", "Table 5", "Figure 8", "ratio to floor"):
        assert heading in out.stdout
    assert len(ResultStore(tmp_path / "ekf" / "noise_levels").done_ids()) == 4       # one per noise level
    assert len(ResultStore(tmp_path / "ekf" / "configurations").done_ids()) == 8     # one per count
    assert (tmp_path / "plots" / "ekf_fig7_boxplots.png").stat().st_size > 1000


def test_campaign_run_takes_a_calibration_study_file(tmp_path):
    text = (CONFIGS / "campaigns" / "calibration_range.toml").read_text()
    path = tmp_path / "range.toml"
    path.write_text(re.sub(r"(?m)^trials = \d+", "trials = 2", text))
    out = cli("campaign", "run", str(path), "--results", str(tmp_path / "r"), "--workers", "1", "--json")
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout)
    assert (summary["ran"], summary["errors"]) == (2, 0)
    assert {r["p_noise_scale"] > 0 for r in ResultStore(tmp_path / "r").rows()} == {True}


def test_an_unknown_study_is_one_line():
    out = cli("calibrate", "study", "nope")
    assert out.returncode == 2 and "error[bad_input]: unknown study" in out.stderr
    assert "Traceback" not in out.stderr and len(out.stderr.strip().splitlines()) == 1
