"""Calibration on set-ups shaped like real ones: a draw-wire on a recorded motion with a narrow
wrist and a far, roughly known anchor (the old Gram-Schmidt identifiability raised "kept columns
are not independent" on these), random set-ups of every instrument on 6-8 joint arms, the
preference of set-up unknowns over arm D-H terms, and a kept set independent of start values."""
from __future__ import annotations

import numpy as np
import pytest

from spacearm.controller.calibration.composite import Block, CompositeProblem
from spacearm.controller.calibration.fit_checks import data_identifiability
from spacearm.controller.calibration.identifiability import find_identifiable
from spacearm.controller.calibration.realistic_setups import draw_wire_case, has_prismatic, random_setup
from spacearm.controller.calibration.trusted_fit import FitOptions, fit_blocks


@pytest.mark.parametrize("seed", [0, 2])       # both raised RuntimeError in the old identifiability
def test_draw_wire_on_a_recorded_motion_fits_to_its_noise_floor(seed):
    case = draw_wire_case(seed)
    assert len(case.blocks[0].Q) == 1000
    q4 = case.blocks[0].Q[:, 3]
    assert np.degrees(q4.max() - q4.min()) <= 10.5
    rep = fit_blocks(case.em, case.blocks, FitOptions(), candidates=case.candidates(), validation=case.validation)
    assert rep.verdict.ok, rep.verdict.message()
    # The anchor start was 0.26 m off: the data's own estimate, not the guess, is the reference.
    assert rep.held_rms("after") <= 1.10 * case.truth_floor()
    # The set-up's unknowns are kept; the arm terms they duplicate are the ones dropped.
    for name in ("wire_ax", "wire_ay", "wire_az", "wire_l0"):
        assert name in rep.result.free, rep.identifiability.summary()
    fitted = rep.result.x[[rep.result.names.index(n) for n in ("wire_ax", "wire_ay", "wire_az")]]
    assert np.linalg.norm(fitted - np.asarray(case.true_model.anchor)) < 0.01


def test_kept_set_does_not_depend_on_the_anchor_start():
    kept = [fit_blocks(c.em, c.blocks, FitOptions(holdout=0.0), candidates=c.candidates()).result.free
            for c in (draw_wire_case(2, start_error=0.15), draw_wire_case(2, start_error=0.02))]
    assert kept[0] == kept[1]


def test_nearly_dependent_columns_never_raise_and_the_kept_set_is_independent():
    case = draw_wire_case(5)
    pr = CompositeProblem(case.em, case.blocks, [])
    cands = case.candidates()
    _, A = pr.residual_and_jacobian(pr.x0)
    A = A[:, 0, [pr.names.index(n) for n in cands]]
    rng = np.random.default_rng(0)
    # Chains of near-duplicates at every scale below and above the tolerance.
    extra = [A[:, 3] + eps * rng.normal(size=len(A)) * np.linalg.norm(A[:, 3]) / len(A) ** 0.5
             for eps in (1e-12, 1e-9, 1e-7, 1e-5, 1e-3)]
    A2 = np.column_stack([A] + extra)
    names = cands + [f"copy_{k}" for k in range(len(extra))]
    pr2 = CompositeProblem(case.em, case.blocks, [])
    pr2.names = tuple(pr2.names) + tuple(names[len(cands):])
    rep = find_identifiable(pr2, names, A=A2, floor=0.0)
    K = A2[:, [names.index(n) for n in rep.kept]]
    K = K / np.linalg.norm(K, axis=0)
    s = np.linalg.svd(K, compute_uv=False)
    assert s[-1] / s[0] > 1e-9
    assert len(rep.kept) + len(rep.dropped) == len(names)


def test_registration_is_kept_before_the_first_joints_d_h_terms():
    case = next(c for c in (random_setup(s) for s in range(40)) if c.blocks[0].label == "point" and c.frames)
    pr = CompositeProblem(case.em, case.blocks, [])
    cands = case.candidates()
    rep = data_identifiability(pr.with_free(cands), cands)
    world = case.em.frame_names("world")
    assert set(world) <= set(rep.kept), rep.summary()
    reasons = {d.name: d.reason for d in rep.dropped}
    assert "theta_1" in reasons or "d_1" in reasons


def test_random_realistic_set_ups_fit_without_an_internal_error():
    """A few of the bench's 200 (bench/bench_calibration_real.py runs them on held-out seeds)."""
    kinds, prismatic = set(), False
    for seed in range(8):
        case = random_setup(seed, max_postures=70)
        rep = fit_blocks(case.em, case.blocks, FitOptions(), candidates=case.candidates(), validation=case.validation)
        assert np.isfinite(rep.held_rms("after"))
        kinds.add(case.blocks[0].label)
        prismatic |= has_prismatic(case)
    assert prismatic and len(kinds) >= 3


# ------------------------------------------------------------------ the command line, as users run it
def _cli():
    import typer
    from typer.testing import CliRunner

    from spacearm.console.commands.calibrate import register
    app = typer.Typer()
    register(app)
    return app, CliRunner()


def _wire_files(tmp_path, case, scale_q=1.0, scale_range=1.0):
    from spacearm.controller.calibration.datafile import write_measurements
    b, v = case.blocks[0], case.validation[0]
    write_measurements(tmp_path / "day1.csv", b.Q * scale_q, "range", b.measured * scale_range)
    write_measurements(tmp_path / "day2.csv", v.Q * scale_q, "range", v.measured * scale_range)
    return tmp_path / "day1.csv", tmp_path / "day2.csv"




def _arm_path():
    from spacearm.base.paths import CONFIGS
    return str(CONFIGS / "arm" / "oru_testbed_6dof.toml")


def test_cli_draw_wire_with_a_rough_anchor_and_a_validation_file(tmp_path):
    import json
    case = draw_wire_case(0, count=300)
    d1, d2 = _wire_files(tmp_path, case)
    rough = np.asarray(case.true_model.anchor) + 0.15          # 0.26 m off, as set by hand
    app, runner = _cli()
    args = ["calibrate", "fit", "--data", str(d1), "--validate", str(d2), "--model", _arm_path(),
            "--anchor", ",".join(map(str, rough)), "--sigma-pos", "5e-4"]
    res = runner.invoke(app, args + ["--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    assert out["ok"] and out["validation_file"]
    assert len(out["held_out"]) == len(case.validation[0].Q)
    assert all("outside" in h for h in out["held_out"])
    assert out["held_out_rms_after"] <= 1.10 * case.truth_floor()
    text = runner.invoke(app, args)
    assert "validation postures (another session)" in text.output


def test_cli_validation_outside_the_training_range_is_flagged(tmp_path):
    case = draw_wire_case(1, count=300)
    b = case.blocks[0]
    q4 = b.Q[:, 3]
    keep = q4 < np.median(q4)                                  # train on one half of the wrist's span
    from spacearm.controller.calibration.datafile import write_measurements
    write_measurements(tmp_path / "half.csv", b.Q[keep], "range", b.measured[keep])
    write_measurements(tmp_path / "other.csv", b.Q[~keep], "range", b.measured[~keep])
    app, runner = _cli()
    res = runner.invoke(app, ["calibrate", "fit", "--data", str(tmp_path / "half.csv"), "--validate",
                              str(tmp_path / "other.csv"), "--model", _arm_path(), "--anchor", "0.5,0,0",
                              "--sigma-pos", "5e-4"])
    assert "postures outside the training range of a joint" in res.output, res.output


def test_cli_refuses_joints_in_degrees_naming_the_unit(tmp_path):
    case = draw_wire_case(3, count=100)
    d1, _ = _wire_files(tmp_path, case, scale_q=180.0 / np.pi)
    app, runner = _cli()
    res = runner.invoke(app, ["calibrate", "fit", "--data", str(d1), "--model", _arm_path(), "--anchor", "0.5,0,0"])
    assert res.exit_code == 2, res.output                # bad input, not a failed fit
    lines = [ln for ln in res.output.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and "degrees" in lines[0] and "limits" in lines[0], res.output
    assert "Traceback" not in res.output


def test_cli_refuses_a_range_column_in_mm_naming_the_unit(tmp_path):
    case = draw_wire_case(3, count=100)
    d1, _ = _wire_files(tmp_path, case, scale_range=1000.0)
    app, runner = _cli()
    res = runner.invoke(app, ["calibrate", "fit", "--data", str(d1), "--model", _arm_path(), "--anchor", "0.5,0,0"])
    assert res.exit_code == 2, res.output                # bad input, not a failed fit
    lines = [ln for ln in res.output.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and "mm" in lines[0] and "reach" in lines[0], res.output


@pytest.mark.parametrize("extra", [["--frames"], ["--fix", "wire_t"], ["--method", "ekf"], ["--kfold", "4"],
                                   ["--sigma-pos", "3e-4"], ["--method", "lse"]])
def test_cli_options_that_used_to_crash_on_the_draw_wire_run_or_refuse_in_one_line(tmp_path, extra):
    case = draw_wire_case(0)                               # the old identifiability raised on this file
    d1, _ = _wire_files(tmp_path, case)
    app, runner = _cli()
    res = runner.invoke(app, ["calibrate", "fit", "--data", str(d1), "--model", _arm_path(),
                              "--anchor", "0.5,0.0,0.0", "--sigma-pos", "5e-4"] + extra)
    assert res.exception is None or isinstance(res.exception, SystemExit), res.output
    assert "Traceback" not in res.output and "RuntimeError" not in res.output
    if res.exit_code != 0:
        assert res.output.strip().splitlines()[-1].startswith(("fit rejected", "error")), res.output
