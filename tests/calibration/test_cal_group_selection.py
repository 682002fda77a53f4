"""D-H groups and joint compliances chosen by leave-one-out error on the training postures only
(`--select-groups`)."""
from __future__ import annotations

import json

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from spacearm.controller.calibration import study_models as S
from spacearm.controller.calibration import trusted_fit as TF
from spacearm.controller.calibration.composite import Block, CompositeProblem
from spacearm.controller.calibration.datafile import write_measurements
from spacearm.controller.calibration.group_selection import dh_group, select_groups
from spacearm.controller.calibration.trusted_fit import FitOptions, fit_blocks

SETUP = ["base_x", "base_rz", "marker_tx", "wire_l0"]                 # the set-up's unknowns: never dropped
DH = [f"{g}_{i}" for g in ("alpha", "a", "theta", "d") for i in (2, 3, 4)]


def _scripted(table: dict[frozenset, float]):
    """cv_error from a table keyed by the set of dropped groups; every call is recorded."""
    calls = []

    def cv_error(names):
        assert set(SETUP) <= set(names), names                      # the set-up's unknowns stay
        dropped = frozenset({dh_group(n) for n in DH} - {dh_group(n) for n in names})
        calls.append(dropped)
        return table.get(dropped, 5.0)
    return cv_error, calls


def test_backward_selection_takes_the_best_drop_and_stops_on_a_small_gain():
    cv, calls = _scripted({frozenset(): 4.0, frozenset({"a"}): 3.2, frozenset({"alpha"}): 3.3,
                           frozenset({"a", "alpha"}): 3.17})           # 0.9 % better: fold noise, not taken
    sel = select_groups(SETUP + DH, cv)
    assert sel.dropped == ("a",) and [s[1] for s in sel.steps] == [4.0, 3.2]
    assert sel.summary().endswith("all 4000.000 mm -> -a_i 3200.000 mm; dropped a_i")
    assert sel.kept == SETUP + [n for n in DH if not n.startswith("a_")]
    assert len(calls) == 1 + 4 + 3
    cv, _ = _scripted({frozenset(): 4.0, frozenset({"a"}): 3.2, frozenset({"a", "alpha"}): 3.0})
    assert select_groups(SETUP + DH, cv).dropped == ("a", "alpha")
    cv, _ = _scripted({})                                             # nothing lowers it
    assert select_groups(SETUP + DH, cv).kept == SETUP + DH
    sel = select_groups(SETUP + DH, lambda names: float("inf"))     # no fold can be fitted
    assert sel.dropped == () and sel.kept == SETUP + DH


def test_each_compliance_is_kept_or_dropped_on_its_own():
    # A compliance is one hypothesis per joint (this drive gives under its load), not a D-H kind:
    # the same criterion drops the one the data only fit to noise and keeps the one they need.
    cands = SETUP + DH + ["k_5", "k_7"]
    table = {frozenset(): 4.0, frozenset({"a"}): 3.2, frozenset({"a", "k_5"}): 2.9, frozenset({"a", "k_7"}): 3.9}

    def cv(names):
        assert set(SETUP) <= set(names), names
        return table.get(frozenset({dh_group(n) for n in cands} - {dh_group(n) for n in names}), 5.0)
    sel = select_groups(cands, cv)
    assert sel.dropped == ("a", "k_5") and "k_7" in sel.kept and "k_5" not in sel.kept
    assert sel.summary().endswith("dropped a_i, k_5")
    assert dh_group("k_7") == "k_7" and dh_group("a_3") == "a" and dh_group("base_x") is None


def _point_blocks(n=36, n_valid=20, seed=4):
    st = S.setup("point")
    rng = np.random.default_rng(seed)
    x = S.true_parameters(st, rng)
    Q = S.valid_postures(st, x, n + n_valid, rng)
    P = S.readings(st, x, Q, rng)
    return st, Q, Block(st.model, Q[:n], P[:n], st.sigma), Block(st.model, Q[n:], P[n:], st.sigma)


def test_the_choice_sees_only_the_training_postures(monkeypatch):
    st, Q, block, valid = _point_blocks()
    seen = []
    real = TF._select

    def spy(em, train, opts, cands, x0):
        seen.append(np.concatenate([b.Q for b in train]))
        return real(em, train, opts, cands, x0)
    monkeypatch.setattr(TF, "_select", spy)
    n = len(block.Q)
    cands = [c for c in CompositeProblem(st.em, [block], []).names if c.startswith(("theta_", "d_", "marker"))]
    rep = fit_blocks(st.em, [block], FitOptions(select_groups=True), candidates=cands, validation=[valid])
    assert len(seen) == 1 and np.array_equal(seen[0], Q[:n])            # every training posture, no other
    assert rep.selection is not None and rep.selection.steps[0][0] == "all"
    assert set(rep.result.free) <= set(rep.selection.kept)
    seen.clear()
    rep = fit_blocks(st.em, [block], FitOptions(select_groups=True, holdout=0.25), candidates=cands)
    held = sorted(h.index for h in rep.held_out)
    assert len(seen) == 1 and np.array_equal(seen[0], np.delete(Q[:n], held, axis=0))   # the training split only


def test_linearised_leave_one_out_matches_refitting_without_each_posture():
    st, Q, block, _ = _point_blocks(n=30)
    cands = [c for c in CompositeProblem(st.em, [block], []).names if c.startswith(("theta_", "d_", "a_", "marker"))]
    rep = fit_blocks(st.em, [block], FitOptions(holdout=0.0), candidates=cands)
    fast = TF.loo_position_rms(CompositeProblem(st.em, [block], rep.result.free), rep.result.x, rep.priors)
    exact = fit_blocks(st.em, [block], FitOptions(kfold=len(block.Q)), candidates=rep.result.free).held_rms("after")
    assert fast == pytest.approx(exact, rel=0.03)
    assert fast > rep.train_position_rms * 1.05           # a prediction, not the training residual


def test_cli_select_groups_reports_the_dropped_groups(tmp_path):
    from spacearm.console.commands.calibrate import register
    st, Q, block, valid = _point_blocks()
    f, v = tmp_path / "day1.csv", tmp_path / "day2.csv"
    write_measurements(f, block.Q, "position", block.measured)
    write_measurements(v, valid.Q, "position", valid.measured)
    app = typer.Typer()
    register(app)
    args = ["calibrate", "fit", "--data", str(f), "--validate", str(v), "--model", str(S.ARMS / "oru_testbed_6dof.toml"),
            "--tool-point", "0.05,0,0.08", "--sigma-pos", "1e-4", "--fix", "alpha_,a_,beta_", "--select-groups"]
    res = CliRunner().invoke(app, args + ["--json"])
    out = json.loads(res.output.splitlines()[0])
    assert isinstance(out["dropped_groups"], list)
    assert not any(n.split("_")[0] in out["dropped_groups"] for n in out["estimate"])


def test_a_negative_compliance_is_rejected_as_impossible_a_small_one_is_noise():
    from spacearm.controller.calibration.fit_checks import Bounds, plausibility
    bounds = Bounds(by_name=(("k_8", 1.0), ("k_5", 0.01)))
    verdict = plausibility("converged", "", ["k_5", "k_8"], np.array([-0.0002, -0.26]), bounds, 1.0, 1.0, 2e-3, 1.9e-3)
    assert not verdict.ok and len(verdict.reasons) == 1 and "k_8" in verdict.reasons[0]
    assert "negatively compliant" in verdict.reasons[0]
    ok = plausibility("converged", "", ["k_5", "k_8"], np.array([-0.0002, 0.26]), bounds, 1.0, 1.0, 2e-3, 1.9e-3)
    assert ok.ok
