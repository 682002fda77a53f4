"""The running mean the diagnosis smooths with keeps the recording's length."""
import numpy as np
import pytest

from spacearm.offline.diagnosis.gear_effects import WINDOW, envelope
from spacearm.offline.diagnosis.running_mean import running_mean


@pytest.mark.parametrize("n", [1, 2, 10, WINDOW - 1, WINDOW, 3 * WINDOW])
def test_envelope_is_as_long_as_the_signal(n):
    x = np.random.default_rng(n).normal(size=n)
    assert envelope(x).shape == (n,)


def test_a_window_longer_than_the_signal_averages_over_the_whole_signal():
    x = np.array([0.0, 3.0, 6.0])
    assert running_mean(x, 25)[1] == pytest.approx(3.0)
    assert np.array_equal(running_mean(x, 1), x)
