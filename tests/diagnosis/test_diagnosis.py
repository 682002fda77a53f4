"""The diagnosis names a concealed effect, fits it, and the fitted plant matches better."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from spacearm.console.main import app
from spacearm.offline.diagnosis.analysis import diagnose
from spacearm.offline.diagnosis.record import record_direct
from spacearm.offline.diagnosis.recording_io import RecordingFormatError, read_table, write_csv
from spacearm.offline.diagnosis.trajectory import Trajectory, save_trajectory
from spacearm.firmware_sim.plant import load_plant_config

NOMINAL = load_plant_config("configs/plant/oru_testbed_nominal.toml")
Q_HOME = np.array([0.0, math.pi / 2, -math.pi / 2, 0.0, -math.pi / 2, 0.0])


def trajectory(seconds: float = 40.0) -> Trajectory:
    t = np.arange(0.0, seconds, 0.02)
    return Trajectory(t, Q_HOME + 0.1 * np.sin(2 * math.pi * t[:, None] / np.array([5, 6, 7, 8, 9, 10])))


def hidden(joint: int | None = None, seed: int = 3, ft: dict | None = None, **effect):
    joints = [j.model_copy(update={"torque_noise": 0.5}) for j in NOMINAL.joints]
    if joint is not None:
        joints[joint] = joints[joint].model_copy(update=effect)
    return NOMINAL.model_copy(update={"joints": joints, "seed": seed, "ft": NOMINAL.ft.model_copy(
        update={"noise_force": 0.3, "noise_torque": 0.01, **(ft or {})})})


def test_coulomb_friction_is_located_named_and_fitted():
    table = record_direct(hidden(2, coulomb_friction=4.0), trajectory(), None, hold_cycles=0)
    result = diagnose(table, NOMINAL)
    first = result.findings[0]
    assert first.fit.effects == ("coulomb",) and first.fit.index == 2
    assert first.params["coulomb_friction"] == pytest.approx(4.0, rel=0.15)
    assert "joint 3: Coulomb friction about" in first.text and "velocity reversal" in first.text
    tau3 = next(c for c in result.channels if c.name == "tau_3")
    assert tau3.significant and tau3.rms_after < 0.6 * tau3.rms_before
    assert result.updated.joints[2].coulomb_friction == pytest.approx(4.0, rel=0.15)


def test_no_effect_gives_no_significant_mismatch():
    table = record_direct(hidden(), trajectory(), None, hold_cycles=0)
    result = diagnose(table, NOMINAL)
    assert result.findings == []
    assert result.verdict.startswith("no significant mismatch")


def test_feedback_latency_is_named_in_cycles():
    table = record_direct(hidden(1, feedback_latency_cycles=2), trajectory(), None, hold_cycles=0)
    result = diagnose(table, NOMINAL)
    assert [(f.fit.effects, f.fit.index, f.params.get("feedback_latency_cycles")) for f in result.findings] == \
        [(("latency",), 1, 2)]


def test_ft_drift_is_named_with_its_rate():
    table = record_direct(hidden(ft={"drift": (0.0, 0.0, 0.02, 0.0, 0.0, 0.0)}), trajectory(), None, hold_cycles=0)
    result = diagnose(table, NOMINAL)
    assert result.findings[0].fit.effects == ("ft_drift",) and result.findings[0].fit.index == 2
    assert result.findings[0].params["drift"] == pytest.approx(0.02, rel=0.15)


def test_column_map_reads_other_peoples_files(tmp_path):
    table = record_direct(hidden(), trajectory(4.0), None, hold_cycles=0)
    path = tmp_path / "theirs.csv"
    write_csv(path, table)
    text = path.read_text().replace("q_cmd_1", "demand_a", 1)
    path.write_text(text)
    with pytest.raises(RecordingFormatError, match="q_cmd"):
        read_table(path)
    mapped = read_table(path, {"q_cmd_1": "demand_a"})
    np.testing.assert_allclose(mapped.q_cmd[:, 0], table.q_cmd[:, 0], atol=1e-9)


def test_console_record_sim_and_diagnose_end_to_end(tmp_path):
    traj = trajectory(12.0)
    save_trajectory(tmp_path / "traj.csv", traj.t, traj.q)
    runner = CliRunner()
    rec = tmp_path / "rec.csv"
    res = runner.invoke(app, ["record-sim", "--plant", "configs/plant/effects/coulomb_joint3.toml",
                              "--trajectory", str(tmp_path / "traj.csv"), "--out", str(rec), "--direct"])
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["diagnose", str(rec), "--report", str(tmp_path / "diag"), "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output)
    assert summary["findings"][0]["effects"] == ["coulomb"] and summary["findings"][0]["joint"] == 3
    assert (tmp_path / "diag" / "report.md").read_text().count("![") >= 1
    fitted = load_plant_config(tmp_path / "diag" / "plant_fitted.toml")
    assert fitted.joints[2].coulomb_friction == pytest.approx(4.0, rel=0.2)


def test_console_rejects_bad_input_with_one_line(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y\n1,2\n")
    res = CliRunner().invoke(app, ["diagnose", str(bad), "--report", str(tmp_path / "d")])
    assert res.exit_code == 2
    res = CliRunner().invoke(app, ["record-sim", "--plant", "configs/plant/oru_testbed_nominal.toml",
                                   "--trajectory", str(bad), "--out", str(tmp_path / "r.csv")])
    assert res.exit_code == 2


def test_backlash_is_named_from_the_hunting_it_causes():
    table = record_direct(hidden(3, backlash=2e-3), trajectory(25.0), None, hold_cycles=0)
    result = diagnose(table, NOMINAL)
    first = result.findings[0]
    assert first.fit.effects == ("backlash",) and first.fit.index == 3
    assert first.params["backlash"] == pytest.approx(2e-3, rel=0.15)
    assert "joint 4: backlash" in first.text


def moves(seconds: float = 40.0) -> Trajectory:
    """Point-to-point moves with rests (quintic profiles), different on every joint."""
    t = np.arange(0.0, seconds, 0.02)
    q = np.repeat(Q_HOME[None, :], len(t), axis=0)
    for j in range(6):
        phase = (t / (4.0 + j)) % 2.0                       # move 1 s, rest the rest of the period
        s = np.clip(phase, 0.0, 1.0)
        step = 10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5
        q[:, j] += 0.15 * np.where(np.floor(t / (4.0 + j)) % 2 == 0, step, 1.0 - step)
    return Trajectory(t, q)


def test_coulomb_beats_viscous_when_it_fits_better_whatever_the_residual_correlation():
    from spacearm.offline.diagnosis.analysis import _best_for_channel
    from spacearm.offline.diagnosis.candidates import Signals, by_name
    from spacearm.offline.diagnosis.fitting import fit_candidate
    t = np.arange(0.0, 60.0, 0.02)
    v = 0.05 * np.sin(2 * math.pi * t / 10.0)
    y = 10.0 * np.sign(v) + np.random.default_rng(1).normal(0.0, 5.0, len(t))
    s = Signals(t, np.cumsum(v) * 0.02, v, np.zeros_like(t), 0.02)
    train = t < 36.0
    fits = [fit_candidate(by_name(name), s, y, train, 0) for name in ("coulomb", "viscous")]
    assert all(f.significant for f in fits)
    # the viscous misfit leaves a long-correlated residual: at its own block length its BIC
    # would win; compared at one block length the better fit wins
    assert _best_for_channel(fits).effects == ("coulomb",)


def test_rests_between_moves_give_no_false_alarm():
    table = record_direct(hidden(seed=5), moves(), None, hold_cycles=0)
    result = diagnose(table, NOMINAL)
    assert result.findings == [] and result.unexplained == []
