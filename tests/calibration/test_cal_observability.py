"""Observability indices and configuration selection."""
from __future__ import annotations

import numpy as np
import pytest

from spacearm.controller.calibration import (board_in_view, configuration_blocks, laser_ok, observability,
                                    random_subsets_best, select_configurations)
from spacearm.controller.calibration.study_laser import candidates


def test_indices_on_known_singular_values():
    G = np.diag([4.0, 2.0, 1.0])
    o = observability(np.vstack([G, np.zeros((1, 3))]))
    assert o["O3"] == pytest.approx(1.0)
    assert o["O2"] == pytest.approx(0.25)
    assert o["O4"] == pytest.approx(0.25)
    assert o["O1"] == pytest.approx(2.0 / 2.0)          # (4*2*1)^(1/3) / sqrt(4 rows)
    assert o["O5"] == pytest.approx(1.0 / (0.25 + 0.5 + 1.0))


def test_selection_beats_random_subsets_and_respects_constraints(laser_setup):
    rng = np.random.default_rng(0)
    cand = candidates(laser_setup, 101, rng)
    probe = laser_setup.problem(cand, np.zeros(len(cand)), 1.0)
    assert laser_ok(probe, cand).all()
    assert laser_setup.model.kin.within_limits(cand.min(0)) and laser_setup.model.kin.within_limits(cand.max(0))
    blocks = configuration_blocks(probe, cand)
    sel = select_configurations(blocks, 50, "O3")
    assert len(set(sel.indices.tolist())) == 50
    direct = observability(blocks[sel.indices].reshape(-1, blocks.shape[-1]))["O3"]
    assert direct == pytest.approx(sel.value, rel=1e-8)
    best, _ = random_subsets_best(blocks, 50, 500, rng)
    assert sel.value > 1.1 * best
    # its time is a figure of bench/bench_calibration.py, not an assert here


@pytest.mark.parametrize("index", ["O1", "O2", "O4", "O5"])
def test_other_indices_improve_on_greedy_start(laser_setup, index):
    cand = candidates(laser_setup, 40, np.random.default_rng(1))
    probe = laser_setup.problem(cand, np.zeros(len(cand)), 1.0)
    blocks = configuration_blocks(probe, cand)
    sel = select_configurations(blocks, 30, index)
    _, vals = random_subsets_best(blocks, 30, 200, np.random.default_rng(2), index)
    assert sel.value >= np.median(vals)


def test_laser_constraint_rejects_beam_away_from_plane(laser_setup):
    cand = candidates(laser_setup, 5, np.random.default_rng(3))
    probe = laser_setup.problem(cand, np.zeros(5), 1.0)
    # Flipping the last joint by pi turns the (offset) beam; reversing the beam must be rejected.
    flipped_plane = probe.x0.copy()
    n0 = probe.model.n_params
    flipped_plane[n0 + 3] = -flipped_plane[n0 + 3] + 100.0     # plane far away: out of range
    assert not laser_ok(probe, cand, flipped_plane).any()


def test_board_in_view():
    T_board_cam = np.eye(4)[None].repeat(3, 0)
    # camera 1 m above the board looking down at it (camera z = -board z)
    T_board_cam[:, :3, :3] = np.diag([1.0, -1.0, -1.0])
    T_board_cam[:, 2, 3] = 1.0
    T_board_cam[1, 0, 3] = 2.0        # board far off-axis
    T_board_cam[2, :3, :3] = np.eye(3)  # looking away
    assert board_in_view(T_board_cam).tolist() == [True, False, False]


def test_selection_on_pose_blocks(ssrms_em):
    from spacearm.controller.calibration import Problem
    Q = ssrms_em.kin.random_configurations(40, np.random.default_rng(4))
    free = [n for n in ssrms_em.dh_names(with_beta=False) if n not in ("d_3", "d_4")]
    pr = Problem(ssrms_em, "pose", Q, np.zeros((40, 4, 4)), free)
    blocks = configuration_blocks(pr, Q)
    assert blocks.shape == (40, 6, 26)
    sel = select_configurations(blocks, 12, "O3")
    best, _ = random_subsets_best(blocks, 12, 300, np.random.default_rng(5))
    assert sel.value >= best
