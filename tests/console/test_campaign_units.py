"""Campaign tables say the unit of every figure and show it in that unit (issue 33: the
tables had bare SI numbers: 0.0012 read as a millimetre or a metre?). Trials with known SI
figures are written to a result directory as the runner writes them; the table is read back
as the operator sees it."""
from __future__ import annotations

import math
import re

import pytest

from spacearm.offline.campaign.figure_units import figure_unit

# SI values as an insertion trial stores them
FIGURES = {"peak_lateral_force": 12.5, "peak_torque": 3.25, "arm_time": 20.0, "final_lateral_error": 0.0012,
           "final_angle_error": math.radians(0.5)}
SHOWN = {"peak_lateral_force": ("N", "12.5"), "peak_torque": ("N m", "3.25"), "arm_time": ("s", "20"),
         "final_lateral_error": ("mm", "1.2"), "final_angle_error": ("deg", "0.5")}


def test_the_summary_table_gives_each_figure_its_unit_and_converts_it(tmp_path, monkeypatch, capsys):
    from spacearm.console.commands.campaign import _print_summary
    from spacearm.offline.campaign.schema import load_campaign
    from spacearm.offline.campaign.store import ResultStore, TrialRecord, code_version
    monkeypatch.setenv("COLUMNS", "200")
    campaign = load_campaign("configs/campaigns/capture.toml")
    store = ResultStore(tmp_path)
    store.open_for(campaign, resume=False)
    for i in range(3):
        store.write(TrialRecord(f"t{i:06d}", i, i, True, None, None, {}, FIGURES, {}, "w", code_version(),
                                campaign.file_hash, 0.0))
    _print_summary(store)
    table = capsys.readouterr().out
    for name, (unit, value) in SHOWN.items():
        row = next((line for line in table.splitlines() if f" {name} " in line), None)
        assert row is not None, table
        cells = [c.strip() for c in re.split(r"[│|]", row) if c.strip()]
        assert cells[1] == unit and cells[3] == value, (name, cells)


@pytest.mark.parametrize("name, unit", [
    ("closed_handover_angle", "deg"), ("open_handover_lateral", "mm"), ("max_tracking_error", "mm"),
    ("final_rotation_error", "deg"), ("position_rms_after", "mm"), ("rotation_rms_after", "deg"),
    ("error_to_floor", "ratio"), ("rms_reduction", "%"), ("closed_success", "0/1"), ("trial_wall_time", "s"),
    ("something_new", "SI")])
def test_a_figure_name_gives_its_unit(name, unit):
    assert figure_unit(name)[0] == unit
