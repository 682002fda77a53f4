"""Impedance control (ORU paper eqs. 13-21): admittance, gravity compensation, the stability
check, and the paper's stiffness experiment on the plant (no bus; HIL version in hil_tests)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from spacearm.base.config.errors import ConfigError
from spacearm.controller.impedance import Admittance, GravityModel, ImpedanceParams, load_impedance
from spacearm.controller.impedance.config import DEFAULT_IMPEDANCE
from spacearm.base.spatial import rpy_to_matrix
from spacearm.offline.contact.trials import ContactTrials, run_stiffness_direct


def test_admittance_with_m_zero_is_the_exact_first_order_step_response():
    k, b, T, f = 1000.0, 500.0, 0.02, 5.0
    adm = Admittance(np.full(6, k), np.full(6, b), T)
    for n in range(1, 200):
        x = adm.update(np.full(6, f))[0]
        assert x == pytest.approx(f / k * (1.0 - math.exp(-k * n * T / b)), rel=1e-9)


def test_admittance_without_stiffness_is_a_damper():
    adm = Admittance(np.zeros(6), np.full(6, 500.0), 0.02)
    for _ in range(50):
        x = adm.update(np.full(6, 2.0))
    assert x[0] == pytest.approx(50 * 0.02 * 2.0 / 500.0)


def test_gravity_compensation_removes_end_effector_and_payload_weight():
    ee = GravityModel(3.0, np.array([0.0, 0.01, 0.08]))
    both = ee.with_payload(2.0, np.array([0.0, 0.0, 0.35]))
    assert both.mass == 5.0 and both.centroid[2] == pytest.approx((3 * 0.08 + 2 * 0.35) / 5)
    rng = np.random.default_rng(3)
    for _ in range(20):
        R = rpy_to_matrix(rng.uniform(-math.pi, math.pi, 3))
        g_sensor = R.T @ np.array([0.0, 0.0, -5.0 * 9.81])
        contact = rng.normal(size=6)
        measured = contact + np.concatenate([g_sensor, np.cross(both.centroid, g_sensor)])
        np.testing.assert_allclose(both.compensate(measured, R), contact, atol=1e-12)


def test_paper_gains_pass_eq19_and_the_sampled_loop_check():
    params = load_impedance()
    assert params.damping == (500.0, 500.0, 500.0, 10.0, 10.0, 10.0)
    assert params.stiffness == (1000.0, 1000.0, 1000.0, 20.0, 20.0, 20.0)
    assert params.insert_force == 2.5 and params.inertia == (0.0,) * 6
    report = params.stability()
    assert report.stable
    for axis in report.axes:
        assert axis.alpha > 1.0 and axis.xi >= axis.xi_required and abs(axis.pole) < 0.95


def test_gains_unstable_in_contact_are_refused_at_configuration_time(tmp_path):
    text = DEFAULT_IMPEDANCE.read_text().replace("damping = [500.0, 500.0, 500.0,", "damping = [5.0, 500.0, 500.0,")
    bad = tmp_path / "impedance.toml"
    bad.write_text(text)
    with pytest.raises(ConfigError, match="unstable in contact"):
        load_impedance(bad)
    with pytest.raises(ValueError):
        ImpedanceParams(stiffness=(1000.0,) * 6, damping=(50.0,) * 6)


def test_stiffness_experiment_on_the_plant_moves_5mm_at_5N():
    """Paper Section 5.2: K = 1 N/mm, B = 50 N s/m on x, 5 N -> 5 mm; y and z within 0.5 mm."""
    result = run_stiffness_direct(ContactTrials())
    assert result.force == pytest.approx(5.0)
    assert abs(result.displacement[0] - 0.005) <= 0.2e-3
    assert np.all(np.abs(result.displacement[1:]) < 0.5e-3)
