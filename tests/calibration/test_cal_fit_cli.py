"""`spacearm calibrate fit` / `next` on generated files: range + point data, rejection, --apply."""
from __future__ import annotations

import json

import numpy as np
import typer
from typer.testing import CliRunner

from spacearm.console.commands.calibrate import register
from spacearm.controller.calibration import study_models as S
from spacearm.controller.calibration.datafile import write_measurements
from spacearm.base.kinematics import load_model

app = typer.Typer()
register(app)
runner = CliRunner()
ARM = S.ARMS / "oru_testbed_6dof.toml"


def _range_and_point_files(tmp_path, n=80, seed=0):
    st = S.setup("range")
    rng = np.random.default_rng(seed)
    x = S.true_parameters(st, rng)
    Q = S.valid_postures(st, x, n, rng)
    fr = tmp_path / "wire.csv"
    write_measurements(fr, Q, "range", S.readings(st, x, Q, rng))
    T = st.em.poses(x, Q)
    fp = tmp_path / "tracker.csv"
    write_measurements(fp, Q, "position", T[:, :3, 3] + rng.normal(0, 1e-4, (n, 3)))
    return st, x, fr, fp


def test_range_data_fit_is_validated_and_plausible(tmp_path):
    st, x, fr, _ = _range_and_point_files(tmp_path)
    anchor = ",".join(str(v) for v in st.model.anchor)
    res = runner.invoke(app, ["calibrate", "fit", "--data", str(fr), "--model", str(ARM), "--anchor", anchor,
                              "--tool-point", "0,0,0.05", "--sigma-pos", "1e-4", "--prior", "wire_a=0.05,joint_angle=0.05",
                              "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    assert out["ok"] and out["status"] == "converged"
    assert out["held_out_rms_after"] < 0.1 * out["held_out_rms_before"]
    assert len(out["held_out"]) == 16 and "wire_l0" in out["estimate"]


def test_range_data_forced_into_the_plane_form_is_rejected(tmp_path):
    _, _, fr, _ = _range_and_point_files(tmp_path)
    h = tmp_path / "as_plane.csv"
    h.write_text(fr.read_text().replace(",range\n", ",h\n", 1))
    res = runner.invoke(app, ["calibrate", "fit", "--data", str(h), "--model", str(ARM), "--plane", "0.3,0.1,1,-1",
                              "--sigma-pos", "1e-4", "--apply", str(tmp_path / "cal.toml")])
    assert res.exit_code == 1
    assert "fit rejected" in res.output and "nothing written" in res.output
    assert not (tmp_path / "cal.toml").exists()


def test_apply_writes_joint_and_base_corrections_that_the_model_reads(tmp_path):
    st, x, fr, fp = _range_and_point_files(tmp_path, n=120)
    out = tmp_path / "cal.toml"
    anchor = ",".join(str(v) for v in st.model.anchor)
    res = runner.invoke(app, ["calibrate", "fit", "--data", str(fp), "--data", str(fr), "--model", str(ARM),
                              "--anchor", anchor, "--tool-point", "0,0,0.05", "--frames", "--sigma-pos", "1e-4",
                              "--apply", str(out), "--json"])
    assert res.exit_code == 0, res.output
    inst = json.loads(res.output.splitlines()[0])["instrument"]
    text = out.read_text()
    # Points and ranges in the base frame show the base; the tool frame is not separable from the
    # measured points' offsets, which stay instrument parameters (provenance comments).
    assert "dbase = [" in text and "# estimated:" in text and "marker_tz" in text
    from spacearm.controller.calibration.errormodel import ErrorModel
    em_cal = ErrorModel.from_kinematics(load_model(out))
    Q = st.em.kin.random_configurations(50, np.random.default_rng(9))
    # The tracked point (tool origin in truth) as the calibrated file plus the fitted marker point
    # (its start estimated from the data, not the --tool-point guess) predicts it.
    t = np.array([inst["marker_tx"], inst["marker_ty"], inst["marker_tz"]])
    T_cal = em_cal.poses(em_cal.nominal, Q)
    p_cal = T_cal[:, :3, 3] + T_cal[:, :3, :3] @ t
    p_true = st.em.poses(x, Q)[:, :3, 3]
    p_nom = st.em.poses(st.em.nominal, Q)[:, :3, 3]
    err = lambda p: np.sqrt(np.mean(np.sum((p - p_true) ** 2, axis=1)))  # noqa: E731
    assert err(p_cal) < 0.1 * err(p_nom)


def test_registration_of_an_external_frame_needs_no_hand_work(tmp_path):
    st = S.setup("point")
    rng = np.random.default_rng(3)
    x = S.true_parameters(st, rng)
    Q = S.valid_postures(st, x, 60, rng)
    from spacearm.base.spatial import rotz, trans
    mocap_T_base = trans(2.0, -1.0, 0.5) @ rotz(2.0)
    P = st.em.poses(x, Q)[:, :3, 3] @ mocap_T_base[:3, :3].T + mocap_T_base[:3, 3]
    f = tmp_path / "mocap.csv"
    write_measurements(f, Q, "position", P + rng.normal(0, 1e-4, P.shape))
    res = runner.invoke(app, ["calibrate", "fit", "--data", str(f), "--model", str(ARM), "--register",
                              "--sigma-pos", "1e-4", "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    assert out["ok"] and out["held_out_rms_after"] < 5e-4


def test_next_proposes_postures_and_bad_input_is_one_line(tmp_path):
    st, x, fr, _ = _range_and_point_files(tmp_path, n=12)
    anchor = ",".join(str(v) for v in st.model.anchor)
    res = runner.invoke(app, ["calibrate", "next", "--data", str(fr), "--model", str(ARM), "--anchor", anchor,
                              "--candidates", "300", "--count", "15", "--out", str(tmp_path / "next.csv")])
    assert res.exit_code == 0, res.output
    assert "unidentifiable" in res.output and "proposed postures" in res.output
    assert len((tmp_path / "next.csv").read_text().splitlines()) == 16
    fit = ["calibrate", "fit", "--data", str(fr), "--model", str(ARM)]
    _bad_input(runner.invoke(app, fit), "need --anchor")
    _bad_input(runner.invoke(app, fit + ["--anchor", "1,x,2"]), "--anchor")
    _bad_input(runner.invoke(app, fit + ["--anchor", "1,2,3", "--bound", "elbow=3"]), "unknown group")
    _bad_input(runner.invoke(app, fit + ["--anchor", "1,2,3", "--prior", "joint_angle=inf"]), "positive and finite")
    _bad_input(runner.invoke(app, fit + ["--anchor", "1,2,3", "--sigma-pos", "0"]), "--sigma-pos")
    _bad_input(runner.invoke(app, fit + ["--anchor", "1,2,3", "--method", "newton"]), "unknown method")
    _bad_input(runner.invoke(app, fit + ["--anchor", "1,2,3", "--register"]), "registration needs point or pose")
    nan = tmp_path / "nan.csv"
    lines = fr.read_text().splitlines()
    nan.write_text("\n".join(lines[:2] + [lines[2].rsplit(",", 1)[0] + ",nan"] + lines[3:]) + "\n")
    _bad_input(runner.invoke(app, ["calibrate", "fit", "--data", str(nan), "--model", str(ARM), "--anchor", "1,2,3"]),
               "non-finite")
    few = tmp_path / "few.csv"
    few.write_text("\n".join(lines[:4]) + "\n")
    _bad_input(runner.invoke(app, ["calibrate", "fit", "--data", str(few), "--model", str(ARM), "--anchor", "1,2,3"]),
               "measure more postures")
    _bad_input(runner.invoke(app, fit + ["--anchor", "1,2,3", "--method", "lse", "--prior", "joint_angle=0.01"]),
               "need --method lm or ekf")
    _bad_input(runner.invoke(app, ["calibrate", "fr3", "--data", str(fr), "--splits", "1"]), "needs column q7")
    _bad_input(runner.invoke(app, ["calibrate", "fr3", "--general", "--method", "newton"]), "unknown method")


def _bad_input(res, words: str) -> None:
    """The console's contract for bad input: exit 2 and one line `error[bad_input]: ...`."""
    lines = [ln for ln in res.output.strip().splitlines() if ln.strip()]
    assert res.exit_code == 2 and len(lines) == 1, res.output
    assert lines[0].startswith("error[bad_input]: ") and words in lines[0], res.output


def test_calibration_table_frame_corrections_are_checked():
    import pytest
    from pydantic import ValidationError

    from spacearm.base.config.arm import Calibration
    ok = Calibration(method="m", date="d", dbase=[0.001, 0, 0, 0, 0, 0.002], dtool=[])
    assert ok.dbase[0] == 0.001
    with pytest.raises(ValidationError, match="6 values"):
        Calibration(method="m", date="d", dtool=[0.0, 0.0])
    with pytest.raises(ValidationError, match="check units"):
        Calibration(method="m", date="d", dbase=[1500.0, 0, 0, 0, 0, 0])


def _tiago_files(tmp_path):
    """The real TIAGo mocap days as a user feeds them to `calibrate fit`: the arm imported from the
    data's URDF with `arm import`, each day as q1..q8,x,y,z (marker 1)."""
    from spacearm.console.main import app as main_app
    from spacearm.controller.calibration.tiago_mocap import TRAINING, URDF, VALIDATION, load_session
    arm = tmp_path / "tiago.toml"
    res = runner.invoke(main_app, ["arm", "import", str(URDF), "--base", "base_link", "--tip", "arm_7_link",
                                   "--out", str(arm)])
    assert res.exit_code == 0, res.output
    days = []
    for source in (TRAINING, VALIDATION):
        Q, P = load_session(source)
        days.append(tmp_path / source.name)
        write_measurements(days[-1], Q, "position", P)
    return arm, days


def test_tiago_arm_6s_compliance_through_the_command_line(tmp_path):
    """`--elasticity` puts the bench's judged TIAGo fit (identify 2021-11-30, validate 2021-11-26)
    in a user's hands: arm_6's drive compliance k_7 is kept, the validation day is within the
    issue's 2.9 mm, better than the rigid fit's; an arm file cannot carry it, so --apply refuses."""
    arm, (train, valid) = _tiago_files(tmp_path)
    base = ["calibrate", "fit", "--data", str(train), "--validate", str(valid), "--model", str(arm), "--register",
            "--select-groups", "--sigma-pos", "1e-3", "--json"]
    rigid = json.loads(runner.invoke(app, base).output)
    res = runner.invoke(app, base + ["--elasticity"])
    assert res.exit_code == 0, res.output
    elastic = json.loads(res.output)
    assert elastic["ok"] and "k_7" in elastic["estimate"] and elastic["estimate"]["k_7"] > 0
    assert elastic["held_out_rms_after"] <= 2.9e-3 < rigid["held_out_rms_after"]
    res = runner.invoke(app, base + ["--elasticity", "--apply", str(tmp_path / "out.toml")])
    assert res.exit_code == 1 and "compliances" in res.output and not (tmp_path / "out.toml").exists()


def test_elasticity_without_link_masses_is_one_line(tmp_path):
    arm, (train, _) = _tiago_files(tmp_path)
    import tomli_w
    import tomllib
    data = tomllib.loads(arm.read_text())
    del data["links"]
    bare = tmp_path / "bare.toml"
    bare.write_text(tomli_w.dumps(data))
    res = runner.invoke(app, ["calibrate", "fit", "--data", str(train), "--model", str(bare), "--register",
                              "--elasticity"])
    assert res.exit_code == 2 and res.output.count("\n") == 1 and "no link masses" in res.output, res.output
