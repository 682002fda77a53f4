"""Studies (small sizes): noise-free exactness, pose accuracy, EKF floor, tables."""
from __future__ import annotations

import numpy as np
import pytest

from spacearm.controller.calibration import study_ekf as E
from spacearm.controller.calibration import study_laser as L
from spacearm.controller.calibration.validation import compare_poses


def test_laser_noise_free_run_recovers_exactly(laser_setup):
    nom, runs = L.run_once(laser_setup, 3, cases=(50,), noise=0.0, methods=("lm",))
    assert nom.rms_pos.max() > 1e-3                        # nominal model is millimetres off
    assert runs[0].stats["lm"].max_pos.max() < 1e-10
    assert runs[0].stats["lm"].max_rot.max() < 1e-10


def test_laser_noisy_run_is_sub_tenth_mm(laser_setup):
    _, runs = L.run_once(laser_setup, 4, cases=(100,), methods=("lm",))
    s = runs[0].stats["lm"]
    assert s.rms_pos.max() < 0.15e-3
    assert s.rms_rot.max() < 0.4e-3


def test_ekf_weighted_lm_close_to_floor():   # fit time: bench/bench_calibration.py
    st = E.setup()
    ratios = []
    for seed in range(2):
        run = E.run_once(st, seed, n_valid=100, methods=("lse", "lm"))
        floor = run.stats["floor"].pos_norm.mean()
        ratios.append(run.stats["lm"].pos_norm.mean() / floor)
        assert run.stats["lm"].pos_norm.mean() < run.stats["lse"].pos_norm.mean()
    assert np.mean(ratios) < 1.15


def test_validation_tables_match_definitions():
    T_true = np.eye(4)[None].repeat(4, 0)
    T_pred = T_true.copy()
    T_pred[:, 0, 3] = [1e-3, -1e-3, 2e-3, 0.0]
    s = compare_poses(T_true, T_pred)
    assert s.rms_pos[0] == pytest.approx(np.sqrt((1 + 1 + 4) / 4) * 1e-3)
    assert s.max_pos[0] == pytest.approx(2e-3)
    assert s.table4()["pos_mean"] == pytest.approx(1e-3)
    assert s.rms_rot.max() == 0.0
