"""Every campaign kind the issue names has a shipped campaign file and runs a tiny campaign on Dask.

The kinds: insertion (and the capture subtask), the changeout approach (closed loop on the
daemon; and open vs closed loop on one draw, bench_oru's), a calibration study per
measurement model (pose, point, range, plane; the laser-ranger and EKF paper studies), the
diagnosis benchmark and the soak (checkout). Each shipped file runs with its trials cut to one or
two, on one LocalCluster the module shares (reached by address: the --scheduler path).
"""
from __future__ import annotations

import re

import pytest

from spacearm.base.paths import CONFIGS
from spacearm.offline.campaign.kinds import KINDS
from spacearm.offline.campaign.runner import run_campaign
from spacearm.offline.campaign.schema import campaign_from_text, load_campaign
from spacearm.offline.campaign.store import ResultStore

pytestmark = pytest.mark.slow

CAMPAIGNS = CONFIGS / "campaigns"
NAMED = {"insertion": "insertion", "capture": "insertion", "approach": "approach",
         "changeout_approach": "changeout_approach",
         "calibration_pose": "calibration_model", "calibration_point": "calibration_model",
         "calibration_range": "calibration_model", "calibration_plane": "calibration_model",
         "calibration_laser": "calibration_laser", "calibration_ekf": "calibration_ekf",
         "diagnosis": "diagnosis", "soak_checkout": "checkout"}
HEAVY = {"approach", "changeout_approach", "soak_checkout", "diagnosis", "capture", "insertion"}    # seconds to a minute a trial


def test_every_named_kind_exists_with_a_campaign_file():
    for name, kind in NAMED.items():
        assert kind in KINDS
        assert load_campaign(CAMPAIGNS / f"{name}.toml").kind == kind
    models = {load_campaign(CAMPAIGNS / f"calibration_{m}.toml").spec.options["model"]
              for m in ("pose", "point", "range", "plane")}
    assert models == {"pose", "point", "range", "plane"}


@pytest.fixture(scope="module")
def scheduler():
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None, silence_logs=40) as cluster:
        yield cluster.scheduler_address


@pytest.mark.parametrize("name", sorted(NAMED))
def test_a_tiny_campaign_of_every_kind(name, scheduler, tmp_path):
    text = (CAMPAIGNS / f"{name}.toml").read_text()
    trials = 1 if name in HEAVY else 2
    campaign = campaign_from_text(re.sub(r"(?m)^trials = \d+", f"trials = {trials}", text), f"{name} (tiny)")
    summary = run_campaign(campaign, tmp_path / name, scheduler=scheduler)
    assert (summary.ran, summary.errors) == (trials, 0)
    rows = ResultStore(tmp_path / name).rows()
    assert len(rows) == trials and (tmp_path / name / "results.parquet").exists()
    worst = f"f_{KINDS[campaign.kind].worst}"
    assert all(r["success"] is False or r.get(worst) is not None for r in rows), rows
