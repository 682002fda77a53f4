"""A parked joint's resolver dither is no unexplained mismatch.

When a joint parks at a target between two resolver readings, its position servo dithers
between them faster than the 50 Hz rows sample it, and the phase of that dither follows the
joint's sub-quantum state, which the recording does not give (its first position is known to a
quantum). So even the true plant replays the dither with another phase: at rest the torque
residual is about sqrt 2 times the dither, where it is a fraction of it while the joint moves.
This happens on `diagnose --run`'s experiment on the separate-process daemon (hil_tests/
test_diagnose_run.py), which starts where the one-speed ramp parked joint 3, and made the
re-diagnosis add "tau_3 unexplained" beside the correct viscous finding. The same recording is
made here on the direct path, started a fraction of a quantum from the first recorded position.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from spacearm.firmware_sim.plant import ARCSEC, load_plant_config
from spacearm.offline.diagnosis.analysis import diagnose, null_replay, replay
from spacearm.offline.diagnosis.direct_sim import on_arm_drives, planned_velocity, simulate
from spacearm.offline.diagnosis.experiment import design_experiment, limits_from_arm
from spacearm.offline.diagnosis.record import DEFAULT_ARM, starting_at
from spacearm.offline.diagnosis.recording_io import RecordingTable

QUANTUM = 25.0 * ARCSEC      # the test bed's resolver step
DT = 0.02
VISCOUS = 200.0              # N m s/rad on joint 3, as in hil_tests/test_diagnose_run.py
NOMINAL = on_arm_drives(load_plant_config("configs/plant/oru_testbed_nominal.toml"), DEFAULT_ARM)
EXAMPLE = load_plant_config("configs/plant/effects/coulomb_joint3.toml")   # 0.5 N m torque noise on every joint
PARKED = np.array([0.0, math.pi / 2, -math.pi / 2 + 0.8, 0.0, -math.pi / 2, 0.0])   # where the HIL ramp ends


def _viscous_plant():
    joints = [j.model_copy(update={"coulomb_friction": 0.0, "viscous_friction": VISCOUS}) if i == 2 else j
              for i, j in enumerate(EXAMPLE.joints)]
    return on_arm_drives(EXAMPLE.model_copy(update={"joints": joints}), DEFAULT_ARM)


def _experiment_recording(sub_quantum: float) -> RecordingTable:
    """Joint 3's designed experiment from where it parked, started `sub_quantum` of a resolver
    step from the target (as the daemon records it: with the velocity offset it sent)."""
    traj = design_experiment([2], PARKED, limits_from_arm(DEFAULT_ARM, 6), DT)
    dq_cmd = planned_velocity(traj.q, DT)
    q0 = PARKED.copy()
    q0[2] += sub_quantum * QUANTUM
    rec = simulate(starting_at(_viscous_plant(), q0), traj.q, DT, q0=q0, dq_cmd=dq_cmd)
    return RecordingTable(rec.t, rec.q_cmd, rec.q, rec.dq, rec.tau, rec.wrench, dq_cmd=dq_cmd)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x ** 2)))


def test_the_true_plant_cannot_replay_a_parked_joints_dither_and_neither_can_the_null():
    """The cause: with the true plant the residual at rest is several times the moving one, and
    two equally valid nominal replays (half a quantum apart) differ at rest by as much."""
    table = _experiment_recording(0.37)
    rest = np.all(np.abs(table.dq_cmd) < 1e-9, axis=1)      # rad/s: the plan stands (rounding only)
    true = replay(table, _viscous_plant())
    residual = table.tau[:, 2] - true.tau[:, 2]
    nominal = replay(table, NOMINAL)
    between_replays = null_replay(table, NOMINAL).tau[:, 2] - nominal.tau[:, 2]
    print(f"true-plant torque residual: {_rms(residual[~rest]):.2g} N m moving, {_rms(residual[rest]):.2g} at rest; "
          f"between two nominal replays at rest {_rms(between_replays[rest]):.2g}; recorded dither at rest "
          f"{np.std(table.tau[rest, 2]):.2g}")
    assert _rms(residual[rest]) > 2.0 * _rms(residual[~rest])
    assert _rms(between_replays[rest]) > 0.7 * _rms(residual[rest])
    assert np.std(table.tau[rest, 2]) > 2.0          # N m: the parked joint does dither (8.6 N m per quantum)


@pytest.mark.parametrize("sub_quantum", [0.13, 0.37, 0.71])
def test_the_experiment_from_a_parked_joint_names_viscous_friction_and_nothing_unexplained(sub_quantum):
    result = diagnose(_experiment_recording(sub_quantum), NOMINAL)
    tau_3 = next(c for c in result.channels if c.name == "tau_3")
    print(f"{result.verdict}; tau_3 {tau_3.excess_after:.2f}x the threshold after the fit")
    assert result.findings and result.findings[0].text.startswith("joint 3: viscous friction"), result.verdict
    assert result.unexplained == [], result.verdict
