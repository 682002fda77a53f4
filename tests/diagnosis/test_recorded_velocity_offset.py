"""The daemon records the velocity offset (60B1h) it sends with each target (`dq_cmd`), and the
diagnosis replays that instead of rebuilding it from the targets (command_timing.py). Recorded by
an in-process lockstep daemon (record_can), as `diagnose --run` records its experiment."""
from __future__ import annotations

import math

import numpy as np
import pytest

import spacearm.offline.diagnosis.record as record_module
from spacearm.controller.recording.csv_export import export_csv
from spacearm.firmware_sim.plant import load_plant_config
from spacearm.offline.diagnosis.command_timing import replay_plant, with_velocity_offset
from spacearm.offline.diagnosis.direct_sim import simulate
from spacearm.offline.diagnosis.experiment import design_experiment, limits_from_arm
from spacearm.offline.diagnosis.record import DEFAULT_ARM, WithVelocityOffset, record_can
from spacearm.offline.diagnosis.recording_io import read_table

NOMINAL = load_plant_config("configs/plant/oru_testbed_nominal.toml")
Q_HOME = np.array([0.0, math.pi / 2, -math.pi / 2, 0.0, -math.pi / 2, 0.0])
DT = 0.02


class SentLog(WithVelocityOffset):
    """The plan of record_can's velocity-offset run, keeping every setpoint it hands the daemon."""
    sent: list[tuple[tuple[float, ...], tuple[float, ...]]] = []

    def sample(self, t: float):
        setpoint = super().sample(t)
        SentLog.sent.append((tuple(setpoint.q), tuple(setpoint.dq)))
        return setpoint


@pytest.fixture(scope="module")
def experiment(tmp_path_factory):
    """Joint 3's designed experiment (several speeds, both ways) recorded by the daemon."""
    SentLog.sent = []
    patch = pytest.MonkeyPatch()
    patch.setattr(record_module, "WithVelocityOffset", SentLog)
    try:
        traj = design_experiment([2], Q_HOME, limits_from_arm(DEFAULT_ARM, 6), DT)
        path = record_can(NOMINAL, traj, tmp_path_factory.mktemp("dq_cmd") / "experiment.mcap", velocity_offset=True)
    finally:
        patch.undo()
    return path, list(SentLog.sent)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x ** 2)))


def test_the_daemons_recording_carries_the_velocity_offset_it_sent(experiment):
    path, sent = experiment
    table = read_table(path)
    assert table.dq_cmd is not None and table.dq_cmd.shape == table.q_cmd.shape
    moving = np.flatnonzero(np.any(table.dq_cmd != 0.0, axis=1))
    sent_moving = sum(1 for _, dq in sent if any(dq))
    assert sent_moving > 100 and abs(len(moving) - sent_moving) <= 2      # the plan's samples, one per cycle
    pairs = set(sent)
    # every row's commanded position and velocity offset is a setpoint the plan handed over, bit for bit
    for k in moving:
        assert (tuple(table.q_cmd[k]), tuple(table.dq_cmd[k])) in pairs, k
    assert float(np.abs(table.dq_cmd[:, 2]).max()) > 0.1                     # rad/s: joint 3's speeds
    assert float(np.abs(table.dq_cmd[:, [0, 1, 3, 4, 5]]).max()) < 1e-12     # the others stand (rounding only)


def test_the_recorded_offset_replays_the_torque_at_least_as_well_as_the_rebuilt_one(experiment):
    table = read_table(experiment[0])
    plant, note = replay_plant(table, NOMINAL)
    assert note is not None and "as recorded" in note
    recorded = simulate(plant, table.q_cmd, table.dt, q0=table.q[0], dq_cmd=table.dq_cmd, joints=[2])
    rebuilt = simulate(with_velocity_offset(NOMINAL), table.q_cmd, table.dt, q0=table.q[0], joints=[2])
    sent_rms, rebuilt_rms = (_rms(table.tau[:, 2] - s.tau[:, 0]) for s in (recorded, rebuilt))
    q_sent, q_rebuilt = (_rms(table.q[:, 2] - s.q[:, 0]) for s in (recorded, rebuilt))
    print(f"torque residual {sent_rms:.3g} N m with the recorded offset, {rebuilt_rms:.3g} rebuilt; "
          f"position {q_sent:.3g} / {q_rebuilt:.3g} rad")
    assert sent_rms <= rebuilt_rms and q_sent <= q_rebuilt


def test_a_csv_export_keeps_the_velocity_offset(experiment, tmp_path):
    path = experiment[0]
    result = export_csv(path, tmp_path / "experiment.csv")
    assert result.columns.count("dq_cmd_3") == 1
    mcap, csv = read_table(path), read_table(tmp_path / "experiment.csv")
    np.testing.assert_array_equal(csv.dq_cmd, mcap.dq_cmd)
    np.testing.assert_array_equal(csv.q_cmd, mcap.q_cmd)
    plant, note = replay_plant(csv, NOMINAL)
    assert note is not None and "as recorded" in note
