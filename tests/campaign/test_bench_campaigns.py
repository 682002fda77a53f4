"""bench_oru's randomised approaches and bench_calibration's laser and EKF studies run their trials
on the campaign runner (one trial or two each, on a LocalCluster the module shares) and print
their tables from the Parquet rows."""
from __future__ import annotations

import importlib.util
import sys

import pytest

from spacearm.base.paths import REPO_ROOT
from spacearm.offline.campaign.store import ResultStore

pytestmark = pytest.mark.slow


def bench(name: str):
    spec = importlib.util.spec_from_file_location(name, REPO_ROOT / "bench" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module        # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def scheduler():
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None, silence_logs=40) as cluster:
        yield cluster.scheduler_address


def test_bench_oru_approaches_fly_open_and_closed_loop_on_one_draw(scheduler, tmp_path):
    oru = bench("bench_oru")
    rows = oru.approaches(1, 5, results=tmp_path / "approaches", scheduler=scheduler)
    trials = ResultStore(tmp_path / "approaches").rows()
    assert len(trials) == 1 and not trials[0]["error"], trials
    trial = trials[0]
    assert trial["p_stage"] == 0.0 and trial["l_store"]           # the first approach of the changeout
    assert trial["f_closed_success"] == float(trial["success"])
    assert trial.get("f_open_handover_lateral") is not None       # the open loop always reaches a handover
    names = [r[0] for r in rows]
    assert "randomised approaches (1 trials), closed loop (vision): success" in names
    assert "randomised approaches (1 trials), open loop, same draws: success" in names
    again = oru.approaches(1, 5, results=tmp_path / "approaches", scheduler=scheduler)   # resumes: nothing re-run
    assert [r[:2] for r in again] == [r[:2] for r in rows]
    assert ResultStore(tmp_path / "approaches").rows()[0]["finished_at"] == trial["finished_at"]


def test_bench_calibration_runs_the_studies_as_campaigns(scheduler, tmp_path, capsys):
    cal = bench("bench_calibration")
    heads = cal.bench_studies(1, 1, (10, 50), results=tmp_path / "studies", scheduler=scheduler)
    printed = capsys.readouterr().out
    for heading in ("laser 100 configs", "Table 4", "Table 5", "EKF study: best method"):
        assert heading in printed
    assert heads["laser"]["rms_pos_mm"][100] and heads["ekf"]["ratios"]
    assert len(ResultStore(tmp_path / "studies" / "laser-ranger").done_ids()) == 1
    assert len(ResultStore(tmp_path / "studies" / "ekf" / "noise_levels").done_ids()) == 4     # one per noise level
    assert len(ResultStore(tmp_path / "studies" / "ekf" / "configurations").done_ids()) == 2   # one per count
