"""The replay latches each command where the recording shows it: a recording whose commands show in
their own row (not the next, as on the daemon's drives) is re-indexed, a daemon-timed one is not."""
from __future__ import annotations

import math

import numpy as np

from spacearm.firmware_sim.plant import load_plant_config
from spacearm.offline.diagnosis.command_timing import align_commands
from spacearm.offline.diagnosis.record import record_direct
from spacearm.offline.diagnosis.trajectory import Trajectory

NOMINAL = load_plant_config("configs/plant/oru_testbed_nominal.toml")
Q_HOME = np.array([0.0, math.pi / 2, -math.pi / 2, 0.0, -math.pi / 2, 0.0])


def _recording():
    t = np.arange(0.0, 8.0, 0.02)
    q = np.repeat(Q_HOME[None, :], len(t), axis=0)
    q[:, 2] += 0.1 * np.sin(2 * math.pi * t / 4.0)
    return record_direct(NOMINAL, Trajectory(t, q), None, hold_cycles=0)


def test_daemon_timed_recording_is_left_as_it_is():
    table = _recording()
    aligned, note = align_commands(table, NOMINAL)
    assert aligned is table and note is None


def test_commands_that_show_in_their_own_row_are_latched_one_row_earlier():
    table = _recording()
    early = table.rows(slice(1, None))            # row k's measurement shows row k's command
    early.q_cmd = table.q_cmd[:-1].copy()
    aligned, note = align_commands(early, NOMINAL)
    assert note is not None and "one row earlier" in note
    np.testing.assert_array_equal(aligned.q_cmd, table.q_cmd[1:-1])
    np.testing.assert_array_equal(aligned.q, table.q[1:-1])
