"""Large stiction between point-to-point moves is named where it also disturbs the runs (issue 31:
85-133 N m of Stribeck friction at 0.013-0.019 rad/s on the concealed bench's point-to-point
moves was answered "mismatch no catalogue effect explains on q_n").

A joint that sticks at 100 N m breaks free late; the servo then drives it back onto its
reference, so the torque stays far off the nominal's well into the move. stick_slip.py takes
the noise on a peak from control windows half-way between starts, where the joint should run:
here those windows show the effect itself (tens of N m), the starts' peaks no longer stood out
against them, and no law was fitted. The null is now taken from the control windows where the
recording runs with the chosen law's replay, and the starts' and those windows' peaks are
compared each with its own scatter (the starts' peaks differ by the move that follows them).

Motion: the concealed bench's point-to-point family (own draws, not a development seed of it),
stiction of two sizes on two joints (110 N m on joint 6, 120 N m on joint 5), one per case.
"""
from __future__ import annotations

import numpy as np
import pytest

from spacearm.offline.diagnosis.analysis import diagnose
from spacearm.offline.diagnosis.physical import parameter_violations
from spacearm.firmware_sim.plant import load_plant_config
from tests.diagnosis.test_bench_concealed_visibility import load_concealed_bench


@pytest.mark.parametrize("draw, joint, level, decay", [(215, 5, 110.0, 0.017), (220, 4, 120.0, 0.016)])
def test_large_stiction_that_disturbs_the_runs_is_named_on_its_joint(draw, joint, level, decay) -> None:
    bench = load_concealed_bench()
    nominal = bench.nominal_for(load_plant_config(bench.base.NOMINAL), 6)
    _, traj = bench.trajectory(np.random.default_rng(draw), 6, 40.0, ("point_to_point",))
    truth = {"stribeck_friction": level, "stribeck_velocity": decay}
    plant = bench.apply_plant(bench.with_joints(nominal, 6, draw),
                              [{"effect": "stribeck", "index": joint, "channel": "tau", "params": truth}])
    result = diagnose(bench.record_direct(plant, traj, None, hold_cycles=0), nominal)
    first = result.findings[0] if result.findings else None
    assert first is not None and first.fit.index == joint and first.fit.effects == ("stribeck",), result.verdict
    # named, not yet sized: 67 and 45 N m stated (+- 11 and 54 at 95 %), the fit's null still
    # taken off every peak
    assert first.params["stribeck_friction"] > 0.0
    assert not parameter_violations(first.params)
