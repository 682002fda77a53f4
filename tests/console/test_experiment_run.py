"""`diagnose --run` moves only the arm it designed the experiment for, and only when it is enabled."""
from __future__ import annotations

import numpy as np
import pytest

from spacearm.console.errors import CommandFailed
from spacearm.console.experiment_run import _check_daemon
from spacearm.offline.diagnosis.experiment import experiment_moves, limits_from_arm

STATUS = {"arm": "oru_testbed_6dof", "state": "enabled", "joints": [{"q_cmd": 0.0}] * 6}


@pytest.mark.parametrize("change, code, words", [
    ({"arm": "ur10"}, "bad_argument", "the daemon runs arm 'ur10'"),
    ({"joints": [{"q_cmd": 0.0}] * 7}, "bad_argument", "has 7 joints, the recording 6"),
    ({"state": "stopped"}, "not_enabled", "the arm is stopped: enable it"),
])
def test_the_wrong_daemon_is_refused_in_one_line(change, code, words):
    with pytest.raises(CommandFailed) as info:
        _check_daemon({**STATUS, **change}, "oru_testbed_6dof", 6)
    assert info.value.code == code and words in str(info.value) and "\n" not in str(info.value)


def test_the_right_daemon_passes():
    _check_daemon(STATUS, "oru_testbed_6dof", 6)


def test_the_moves_stay_within_the_limits_and_end_where_they_started():
    limits = limits_from_arm("configs/arm/oru_testbed_6dof.toml", 6)
    start = np.array([0.0, 1.5, -1.4, 0.0, -1.5, 0.0])
    moves = experiment_moves([1], start, limits)
    assert len(moves) == 6 and {m.joint for m in moves} == {1}
    assert all(0.0 < m.speed <= 1.0 for m in moves)          # move_joints' speed: a fraction of the limits
    assert all(limits[1].lower <= m.target[1] <= limits[1].upper for m in moves)
    np.testing.assert_allclose(moves[-1].target, start, atol=1e-12)
