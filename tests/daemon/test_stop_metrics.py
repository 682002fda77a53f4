"""The stop judge on positions as a resolver reads them: a servo's settling overshoot inside
the standstill window is a stop at rest, a joint that really travels back is not."""
from __future__ import annotations

import numpy as np
import pytest

from spacearm.controller.daemon.stop_metrics import REST_TOLERANCE, stop_figures

RESOLVER_STEP = np.radians(25 / 3600)
V_LIMIT, A_LIMIT = 0.17453292519943295, 0.3490658503988659


def _stop_with_overshoot(period: float, v: float, overshoot: float, settle: float, offset: float):
    """Cruise at v, stop at t = 1 s at A_LIMIT, then a bump of `overshoot` rad past the rest
    position that returns with time constant `settle` s; read through the resolver."""
    t = np.arange(0.0, 4.0, period)
    t_rest = 1.0 + v / A_LIMIT
    q = np.where(t < 1.0, v * t, v * 1.0 + v * (t - 1.0) - 0.5 * A_LIMIT * (t - 1.0) ** 2)
    q = np.where(t < t_rest, q, v + v * v / (2 * A_LIMIT))
    after = np.clip(t - t_rest, 0.0, None) / settle
    q = q + overshoot * after * np.exp(1.0 - after)
    read = np.floor((q + offset) / RESOLVER_STEP) * RESOLVER_STEP
    return t, read[:, None]


@pytest.mark.parametrize("period", [0.004, 0.02])
@pytest.mark.parametrize("overshoot", [0.11e-3, 0.17e-3])
def test_a_servo_settling_inside_the_standstill_window_is_not_moving_back(period, overshoot):
    """The drives' measured overshoot (0.11-0.17 mrad) at every phase of the resolver's steps."""
    for offset in np.linspace(0.0, RESOLVER_STEP, 9, endpoint=False):
        for settle in (0.02, 0.05, 0.1):
            t, q = _stop_with_overshoot(period, 0.1, overshoot, settle, offset)
            f = stop_figures(t, q, 1.0, np.array([V_LIMIT]), np.array([A_LIMIT]), period)[0]
            assert not [p for p in f.problems() if "back" in p], (offset, settle, f)


@pytest.mark.parametrize("period", [0.004, 0.02])
@pytest.mark.parametrize("overshoot, settle", [(0.6e-3, 0.05), (0.4e-3, 0.3), (2e-3, 0.1)])
def test_a_joint_that_travels_back_after_the_stop_is_reported(period, overshoot, settle):
    """Travel back slow enough for every speed check (0.4 mrad over 0.3 s) or fast: reported."""
    for offset in np.linspace(0.0, RESOLVER_STEP, 5, endpoint=False):
        t, q = _stop_with_overshoot(period, 0.1, overshoot, settle, offset)
        f = stop_figures(t, q, 1.0, np.array([V_LIMIT]), np.array([A_LIMIT]), period)[0]
        assert f.back_travel > REST_TOLERANCE
        assert any("moved back" in p for p in f.problems()), f
