"""Stops judged by what the joints did (issue 28): a joint at full speed, stopped mid-motion,
must never speed up, must decelerate monotonically and come to rest within v^2/2a + one
cycle's travel (+10 %) and v/a + 2 cycles, judged from the recorded measured positions."""
from __future__ import annotations

import numpy as np
import pytest

from spacearm.controller.daemon.stop_metrics import stop_figures
from tests.daemon.stop_run import stepped_daemon


def _judge(run, joints=None):
    t, q, events, _ = run.recording()
    stops = [e for e in events if e["kind"] == "protective_stop"]
    assert stops, events
    model = run.daemon.model
    a_max = np.array([j.limits.acceleration for j in run.daemon.arm.joints])
    figures = stop_figures(t, q, stops[0]["t"], np.array(model.v_max), a_max, run.daemon.options.period, joints)
    return figures, stops


@pytest.mark.parametrize("joint", [0, 3])
def test_operator_stop_at_full_speed_never_speeds_the_joint_up(tmp_path, joint):
    with stepped_daemon(tmp_path) as run:
        run.enable()
        run.jog_at_full_speed(joint)
        run.apply(run.core.cmd_stop)
        run.cycles(60)
        figures, stops = _judge(run)
    assert stops[0]["code"] == "operator_stop"
    moving = figures[joint]
    print(moving.row())
    assert moving.v_stop > 0.98 * moving.limit
    problems = [p for f in figures for p in f.problems()]
    assert not problems, problems
