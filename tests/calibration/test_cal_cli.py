"""`spacearm calibrate` commands on generated data files."""
from __future__ import annotations

import numpy as np
import typer
from typer.testing import CliRunner

from spacearm.console.commands.calibrate import register
from spacearm.controller.calibration.datafile import write_measurements
from spacearm.controller.calibration.study_ekf import ARM_FILE, setup
from spacearm.controller.calibration.study_laser import ARM_FILE as LASER_ARM, candidates

app = typer.Typer()
register(app)
runner = CliRunner()


def test_fit_pose_file_recovers_theta_error(tmp_path):
    st = setup()
    Q = st.model.kin.random_configurations(30, np.random.default_rng(0))
    x = st.model.with_errors({"theta_2": 1e-3, "a_4": 2e-3})
    f = tmp_path / "poses.csv"
    write_measurements(f, Q, "pose", st.model.poses(x, Q))
    res = runner.invoke(app, ["calibrate", "fit", "--data", str(f), "--model", str(ARM_FILE), "--json"])
    assert res.exit_code == 0, res.output
    import json
    out = json.loads(res.output)
    assert out["status"] == "converged"
    assert abs(out["estimate"]["theta_2"] - 1e-3) < 1e-9
    assert abs(out["estimate"]["a_4"] - 2e-3) < 1e-9
    assert "d_3" in out["dropped"]


def test_fit_distance_file_with_plane(tmp_path, laser_setup):
    Q = candidates(laser_setup, 60, np.random.default_rng(1))
    h = laser_setup.problem(Q, np.zeros(len(Q)), 1.0).predict(laser_setup.x_true, Q)
    f = tmp_path / "dist.csv"
    write_measurements(f, Q, "plane", h)
    res = runner.invoke(app, ["calibrate", "fit", "--data", str(f), "--model", str(LASER_ARM),
                              "--plane", "0,1,4.6,-0.69", "--method", "lse"])
    assert res.exit_code == 0, res.output
    assert "identifiable: 26 parameters" in res.output
    assert "plane_nz" in res.output


def test_fit_errors_are_one_line(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("q1,q2\n0,0\n")
    res = runner.invoke(app, ["calibrate", "fit", "--data", str(bad), "--model", str(ARM_FILE)])
    assert res.exit_code == 2 and res.output.startswith("error[bad_input]: ")      # bad input, not a failed fit
    assert "needs columns" in res.output
    res = runner.invoke(app, ["calibrate", "study", "nope"])
    assert res.exit_code == 2 and "unknown study" in res.output
