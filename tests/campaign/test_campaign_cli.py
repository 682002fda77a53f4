"""`spacearm campaign` on the command line: bad input is one line, a killed run resumes losing nothing."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from spacearm.base.paths import REPO_ROOT
from spacearm.offline.campaign.schema import trial_id
from spacearm.offline.campaign.store import ResultStore

SPACEARM = [sys.executable, "-m", "spacearm.console.main"]


def cli(*args: str, timeout: float = 240) -> subprocess.CompletedProcess:
    return subprocess.run([*SPACEARM, "campaign", *args], capture_output=True, text=True, timeout=timeout,
                          cwd=REPO_ROOT)


@pytest.mark.parametrize("args, code", [
    (["run", "no_such_campaign"], 2),
    (["run", "insertion_smoke", "--scheduler", "http://x"], 2),
    (["replay", "/nonexistent/results", "t000001"], 1),
    (["report", "/nonexistent/results"], 1),
])
def test_bad_input_is_one_line_without_traceback(args, code):
    out = cli(*args)
    assert out.returncode == code
    assert "Traceback" not in out.stderr and len(out.stderr.strip().splitlines()) == 1
    assert out.stderr.startswith("error")


@pytest.mark.slow
def test_campaign_killed_half_way_resumes_with_nothing_lost_or_run_twice(tmp_path, ekf_campaign):
    """SIGKILL the whole `campaign run` (client and its LocalCluster) mid-way, then --resume."""
    campaign = ekf_campaign(trials=40)
    results = tmp_path / "r"
    proc = subprocess.Popen([*SPACEARM, "campaign", "run", str(campaign), "--results", str(results),
                             "--workers", "1", "--json"], cwd=REPO_ROOT, start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 180
    try:
        while time.monotonic() < deadline and len(ResultStore(results).done_ids()) < 10:
            time.sleep(0.05)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)      # the process group this test started
        proc.wait(10)
    before = {p.name: p.stat().st_mtime_ns for p in (results / "trials").glob("t*.parquet")}
    assert 10 <= len(before) < 40, f"{len(before)} trials finished before the kill"
    out = cli("run", str(campaign), "--results", str(results), "--workers", "1", "--resume", "--json")
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout)
    after = {p.name: p.stat().st_mtime_ns for p in (results / "trials").glob("t*.parquet")}
    assert sorted(after) == [f"{trial_id(i)}.parquet" for i in range(40)]            # none lost
    assert all(after[name] == mtime for name, mtime in before.items())                 # none re-run
    assert summary["skipped"] == len(before) and summary["ran"] == 40 - len(before)
    assert not list((results / "trials").glob(".*.tmp"))
