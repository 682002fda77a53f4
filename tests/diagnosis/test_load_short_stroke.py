"""A load on a rotary joint that moves a short stroke (the concealed bench's new families: the
Panda recording's motions, slow ramps, point-to-point moves) is a constant plus a slight slope
there. The constant is known well, the slope poorly, and with it the load's amplitude and
angle; judged by the amplitude's error, such loads were dropped as "size unknown" and the
joint called unexplained (4 of 15 load cases on dev seed 8001, 4.9 +- 19 N m for a 3.5 N m
load). Whether a load is there is judged by its torque over the stroke."""
from __future__ import annotations

import math

import numpy as np
import pytest

from tests.diagnosis.test_bench_concealed_visibility import load_concealed_bench


@pytest.fixture(scope="module")
def short_stroke_load():
    bench = load_concealed_bench()
    from spacearm.firmware_sim.plant import load_plant_config
    from spacearm.offline.diagnosis.analysis import diagnose
    from spacearm.offline.diagnosis.trajectory import Trajectory
    nominal = bench.nominal_for(load_plant_config(bench.base.NOMINAL), 6)
    t = np.arange(0.0, 40.0, bench.DT)
    q = np.repeat(bench.home(6)[None, :], len(t), axis=0) + bench._panda_motion(np.random.default_rng(4), t, 6)
    params = {"gravity_torque": 4.0, "gravity_angle": -1.45}     # nearly its peak at the joint's home, pi/2
    truths = [{"effect": "gravity_load", "index": 1, "channel": "tau", "params": params}]
    table = bench.record_direct(bench.apply_plant(bench.with_joints(nominal, 6, 11), truths), Trajectory(t, q), None,
                                hold_cycles=0)
    return table, diagnose(table, nominal), params


def test_a_load_over_a_short_stroke_is_named_on_its_joint(short_stroke_load) -> None:
    table, result, _ = short_stroke_load
    assert np.ptp(table.q[:, 1]) < 0.2          # a short stroke: a few degrees
    assert result.findings, result.verdict
    top = result.findings[0]
    assert top.fit.index == 1 and top.fit.effects == ("gravity_load",), result.verdict


def test_its_torque_over_the_stroke_is_stated_and_holds(short_stroke_load) -> None:
    from spacearm.offline.diagnosis.honesty import load_at_centre
    table, result, params = short_stroke_load
    top = result.findings[0]
    torque, err, centre = load_at_centre(top.fit, table.q[:, 1])
    true = params["gravity_torque"] * math.cos(centre + params["gravity_angle"])
    assert abs(torque - true) <= max(1.96 * err, 0.15 * abs(true)), (torque, err, true)
    if "over this stroke" in top.text:
        assert "amplitude and angle are not" in top.text
