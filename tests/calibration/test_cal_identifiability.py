"""Identifiability: the laser paper's 25 (+ the plane coefficient), reasons, determinism."""
from __future__ import annotations

import numpy as np

from spacearm.controller.calibration import Problem, find_identifiable

PAPER_25 = [f"{k}_{j}" for j in range(1, 7) for k in ("theta", "alpha", "a", "d")
            if (k, j) != ("d", 2)] + ["beta_2", "beta_6"]


def _laser_candidates(em, plane):
    return [n for n in em.names if not n.startswith(("base_", "tool_"))] + plane.names


def test_laser_arm_gives_the_papers_25(laser_em, paper_plane):
    cands = _laser_candidates(laser_em, paper_plane)
    pr = Problem(laser_em, "plane", np.zeros((1, 6)), np.zeros(1), cands, plane=paper_plane)
    rep = find_identifiable(pr, cands, gauge="plane_ny")
    robot = [n for n in rep.kept if not n.startswith("plane_")]
    assert sorted(robot) == sorted(PAPER_25)
    assert [n for n in rep.kept if n.startswith("plane_")] == ["plane_nz"]   # the 4.6 coefficient
    reasons = {d.name: d.reason for d in rep.dropped}
    assert set(reasons) == {"beta_1", "d_2", "beta_3", "beta_4", "beta_5",
                            "plane_nx", "plane_ny", "plane_f"}
    assert "d_3" in reasons["d_2"] and "parallel axes 2,3" in reasons["d_2"]
    for j in (1, 3, 4, 5):
        assert f"theta_{j}" in reasons[f"beta_{j}"]
    assert "d_1" in reasons["plane_f"]
    assert rep.rank == 26


def test_deterministic_and_independent_of_candidate_order(laser_em, paper_plane):
    cands = _laser_candidates(laser_em, paper_plane)
    pr = Problem(laser_em, "plane", np.zeros((1, 6)), np.zeros(1), cands, plane=paper_plane)
    a = find_identifiable(pr, cands, gauge="plane_ny")
    b = find_identifiable(pr, list(reversed(cands)), gauge="plane_ny")
    assert sorted(a.kept) == sorted(b.kept)
    assert a.kept == find_identifiable(pr, cands, gauge="plane_ny").kept


def test_full_pose_on_ssrms_drops_the_d_of_parallel_pitch_axes(ssrms_em):
    cands = ssrms_em.dh_names(with_beta=False)
    pr = Problem(ssrms_em, "pose", np.zeros((1, 7)), np.zeros((1, 4, 4)), cands)
    rep = find_identifiable(pr, cands)
    assert [d.name for d in rep.dropped] == ["d_3", "d_4"]
    assert len(rep.kept) == 26


def test_frames_overlapping_the_chain_are_dropped(ssrms_em):
    # World-frame translations/rotations duplicate joint-1 parameters; all 12 frame parameters
    # plus 28 D-H cannot all be identifiable from poses.
    cands = ssrms_em.dh_names(with_beta=False) + ssrms_em.frame_names("world") + ssrms_em.frame_names("tool")
    pr = Problem(ssrms_em, "pose", np.zeros((1, 7)), np.zeros((1, 4, 4)), cands)
    rep = find_identifiable(pr, cands)
    assert len(rep.kept) == rep.rank < len(cands)
    assert all(d.reason for d in rep.dropped)
