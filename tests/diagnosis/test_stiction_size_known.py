"""Stiction sized by replays (judged by its breakaway peaks or its swing) is reported only
where its size is known to half its value, like every sample-judged fit (issue 31: 1.09 +- 2.9
N m of stiction was named on a joint with no effect at all, development seed 5402)."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from spacearm.offline.diagnosis.analysis import ChannelResult, _findings
from spacearm.offline.diagnosis.fitting import ChannelFit

ROWS = 500


def stiction(level: float, stderr: float, judged_by: str) -> ChannelFit:
    return ChannelFit(("stribeck",), "tau", 0, np.array([level]), np.array([stderr]), ("stribeck_friction",),
                      (0.004,), 1.0, 2.0, 1.0, 0.5, 0.0, 1, prediction=np.zeros(ROWS), n_train=300, n_params=2,
                      judged_by=judged_by)


def judged(fit: ChannelFit):
    channels = [ChannelResult("q_1", 1e-4, 1e-4, 1e-4), ChannelResult("tau_1", 0.5, 1.0, 0.5)]
    t = np.arange(ROWS) * 0.02
    quiet = SimpleNamespace(dq=(0.01 * np.sin(2 * math.pi * t / 10.0))[:, None])
    return _findings([fit], channels, {"tau_1": np.zeros(ROWS)}, quiet, t, {}, ["revolute"])


def test_stiction_of_unknown_size_is_not_reported():
    for judged_by in ("breakaway", "envelope"):
        findings, rejected = judged(stiction(1.09, 2.9 / 1.96, judged_by))
        assert not findings and rejected, judged_by


def test_stiction_of_known_size_is_reported():
    findings, rejected = judged(stiction(20.0, 1.0, "breakaway"))
    assert findings and not rejected
