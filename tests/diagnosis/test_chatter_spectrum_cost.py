"""Stiction changes how the drive chatters as much as a gear does, and its replay (stick_slip.py)
chatters as the recording does: where that replay already matches the recording's chatter
spectrum, the grid of stiffness replays (chatter_spectrum.py) is not run. It ran on every joint
named stiction by its breakaway, and the development bench's diagnosis took 18 s a recording
instead of 4."""
from __future__ import annotations

import numpy as np

from spacearm.offline.diagnosis import analysis

from test_stiction_breakaway import NOMINAL, recorded


def test_stiction_whose_replay_chatters_as_recorded_runs_no_stiffness_grid(monkeypatch):
    runs = []
    fit = analysis.fit_spectral_gear
    monkeypatch.setattr(analysis, "fit_spectral_gear", lambda *a, **k: runs.append(1) or fit(*a, **k))
    result = analysis.diagnose(recorded(stribeck_friction=9.0, stribeck_velocity=0.0106), NOMINAL)
    assert [f.fit.effects for f in result.findings] == [("stribeck",)], result.verdict
    assert result.findings[0].fit.judged_by == "breakaway"
    assert runs == []


def test_a_recording_too_short_for_a_spectrum_is_not_screened_in():
    """Ten rows make no Welch segment: the screen said ValueError (tests/fuzz, seven joints, ten rows)."""
    from spacearm.offline.diagnosis.chatter_spectrum import screened
    x = np.random.default_rng(1).normal(size=10)
    assert not screened(x, 0 * x, 0 * x, 0 * x, np.arange(10) < 6)
