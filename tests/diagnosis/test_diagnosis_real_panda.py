"""The real Panda recording (Gaz et al., RA-L 2019; ../shared/data/panda_gaz2019): friction is
named on every joint, held-out torque RMS reaches the published model's, and the URDF that
still carries the hand shows the hand's mass as a payload error."""
from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from spacearm.console.main import app

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared" / "data" / "panda_gaz2019"
REC = DATA / "exciting_traj_1.csv"
PUBLISHED_HELDOUT = (0.42, 0.84, 0.45, 0.52, 0.15, 0.14, 0.07)   # the data README: Gaz model + Table I friction
PUBLISHED_FC = (0.2450, 0.1523, 0.1827, 0.3591, 0.2669, 0.1658, 0.2109)  # Table III, RE
PUBLISHED_FC_CLS = (0.2549, 0.1413, 0.1879, 0.3625, 0.2728, 0.1529, 0.2097)  # Table III, CLS

pytestmark = pytest.mark.skipif(not REC.exists(), reason="shared Panda data not present")


def run(urdf: str, tmp_path: Path) -> dict:
    res = CliRunner().invoke(app, ["diagnose", str(REC), "--command", "measured", "--rate", "100", "--urdf",
                                   str(ROOT / "configs/urdf/panda" / urdf), "--heldout-from", "14.5",
                                   "--report", str(tmp_path / "d"), "--json"])
    assert res.exit_code == 0, res.output
    return json.loads(res.output)


def test_panda_friction_is_named_and_heldout_torque_reaches_the_published_model(tmp_path):
    out = run("panda_arm_no_hand.urdf", tmp_path)
    coulomb = {f["joint"]: f["parameters"]["coulomb_friction"] for f in out["findings"]
               if f["joint"] is not None and "coulomb" in f["effects"]}
    assert sorted(coulomb) == [1, 2, 3, 4, 5, 6, 7]
    for j, fc in coulomb.items():
        assert 0.5 * PUBLISHED_FC[j - 1] < fc < 1.6 * PUBLISHED_FC[j - 1]
    # the torque column runs ~5 ms ahead of q, dq; fitted unaligned, joint 2's Coulomb level came
    # out 0.229 N m (+62 % on the published least-squares value) with no viscous friction
    assert 0.002 <= out["torque_time_offset_s"] <= 0.01, out["verdict"]
    # the robot-reported dq is 5-6 ms behind dq/dt of q on every joint (the recording's own kinematics)
    assert 0.004 <= out["velocity_column_lag_s"] <= 0.007, out["verdict"]
    assert coulomb[2] == pytest.approx(PUBLISHED_FC_CLS[1], rel=0.25)
    within = [j for j, fc in coulomb.items() if abs(fc - PUBLISHED_FC_CLS[j - 1]) <= 0.15 * PUBLISHED_FC_CLS[j - 1]]
    assert len(within) >= 5, coulomb        # the target is 6; bench_diagnosis_real prints the figure
    for j in out["joints"]:
        assert j["heldout_rms_fitted"] < 0.85 * j["heldout_rms_nominal"]
        assert j["heldout_rms_fitted"] <= 1.05 * PUBLISHED_HELDOUT[j["joint"] - 1]


def test_panda_urdf_with_the_hand_shows_a_payload_error_of_the_hand_mass(tmp_path):
    out = run("panda.urdf", tmp_path)
    payload = [f for f in out["findings"] if f["effects"] == ["payload"]]
    assert len(payload) == 1
    assert payload[0]["parameters"]["payload_mass"] == pytest.approx(-0.76, rel=0.15)
