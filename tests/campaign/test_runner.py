"""The Dask runner on an embedded LocalCluster: results per trial, resume, replay, a killed worker."""
from __future__ import annotations

import statistics

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from spacearm.offline.campaign.replay import replay
from spacearm.offline.campaign.report import write_report
from spacearm.offline.campaign.runner import run_campaign
from spacearm.offline.campaign.schema import load_campaign, trial_id
from spacearm.offline.campaign.store import ResultStore, StoreError

pytestmark = pytest.mark.slow


def test_resumed_campaign_skips_done_trials_and_equals_a_one_shot_run(tmp_path, ekf_campaign):
    campaign = load_campaign(ekf_campaign(trials=8))
    part = run_campaign(campaign, tmp_path / "resumed", workers=1, limit=3)
    assert (part.ran, part.skipped) == (3, 0)
    with pytest.raises(StoreError, match="--resume"):
        run_campaign(campaign, tmp_path / "resumed", workers=1)
    rest = run_campaign(campaign, tmp_path / "resumed", workers=2, resume=True)
    assert (rest.ran, rest.skipped, rest.errors) == (5, 3, 0)
    one_shot = run_campaign(campaign, tmp_path / "one_shot", workers=2)
    assert (one_shot.ran, one_shot.skipped, one_shot.errors) == (8, 0, 0)
    resumed = ResultStore(tmp_path / "resumed")
    assert sorted(resumed.done_ids()) == [trial_id(i) for i in range(8)]
    assert resumed.outcomes() == ResultStore(tmp_path / "one_shot").outcomes()
    merged = pq.read_table(tmp_path / "resumed" / "results.parquet")
    assert merged.num_rows == 8 and set(merged.column("campaign_hash").to_pylist()) == {campaign.file_hash}
    assert all(v for v in merged.column("code_version").to_pylist())
    assert merged.schema.metadata[b"spacearm.campaign_text"].decode() == campaign.text
    report = write_report(resumed)
    assert (report.parent / "success.png").stat().st_size > 1000
    text = report.read_text()
    assert "Wilson" in text and "Worst trials" in text and text.count("| t0000") == 5
    # figures are stored in SI and shown with their unit: a position error in mm
    row = next(line for line in text.splitlines() if line.startswith("| position_rms_after |"))
    unit, _, median = (cell.strip() for cell in row.split("|")[2:5])
    stored = statistics.median(v for v in merged.column("f_position_rms_after").to_pylist() if v is not None)
    assert unit == "mm" and float(median) == pytest.approx(1e3 * stored, rel=1e-3)


def test_a_different_campaign_file_is_refused_in_the_same_directory(tmp_path, ekf_campaign):
    run_campaign(load_campaign(ekf_campaign(trials=2)), tmp_path / "r", workers=1)
    other = load_campaign(ekf_campaign(seed=99, trials=2, name="other.toml"))
    with pytest.raises(StoreError, match="not this file"):
        run_campaign(other, tmp_path / "r", workers=1, resume=True)


def test_replay_of_one_trial_matches_and_a_tampered_figure_does_not(tmp_path, ekf_campaign):
    run_campaign(load_campaign(ekf_campaign(trials=3)), tmp_path / "r", workers=1)
    result = replay(tmp_path / "r", "t000002")
    assert result.matches and result.parameters_equal and result.figures
    path = tmp_path / "r" / "trials" / "t000002.parquet"
    row = pq.read_table(path).to_pylist()[0]
    row["f_position_rms_after"] *= 1.001
    pq.write_table(pa.Table.from_pylist([row]), path)
    tampered = replay(tmp_path / "r", "t000002")
    assert not tampered.matches
    assert [f.name for f in tampered.figures if not f.equal] == ["position_rms_after"]


def test_a_trial_that_raises_is_recorded_as_broken_and_the_campaign_goes_on(tmp_path):
    """A start pose out of reach makes the insertion raise: an error row, not a lost campaign."""
    path = tmp_path / "reach.toml"
    path.write_text('[campaign]\nname = "reach"\nkind = "insertion"\nseed = 1\ntrials = 2\nretries = 0\n'
                    '[parameters.lateral_radius]\nlow = 2.0\nhigh = 2.0\n')
    summary = run_campaign(load_campaign(path), tmp_path / "r", workers=1)
    assert (summary.ran, summary.errors) == (2, 2)
    rows = ResultStore(tmp_path / "r").rows()
    assert all("unreachable" in r["error"] and not r["success"] for r in rows)
    report = write_report(ResultStore(tmp_path / "r")).read_text()
    assert "0 / 0 / 2" in report
