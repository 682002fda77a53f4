"""A finding on one joint may not make another joint's held-out error worse (sim path): the
pooled figure of a fix hides a joint it spoils. Judged on the re-simulation's per-channel
results, without simulating anything here."""
from __future__ import annotations

import numpy as np

from spacearm.offline.diagnosis.analysis import ChannelResult, _made_worse
from spacearm.offline.diagnosis.fitting import ChannelFit


def coulomb_on(joint: int) -> ChannelFit:
    return ChannelFit(("coulomb",), "tau", joint, np.array([2.0]), np.array([0.1]), ("coulomb_friction",),
                      (float("nan"),), 1.0, 4.0, 1.0, 0.5, 1e-9, 1)


def channels(tau3_after: float) -> list[ChannelResult]:
    out = []
    for j in range(3):
        out.append(ChannelResult(f"q_{j + 1}", 1e-4, 2e-4, 2e-4))
        out.append(ChannelResult(f"tau_{j + 1}", 0.1, 1.0, 0.5 if j == 0 else 1.0))
    out[-1].rms_after = tau3_after
    return out


def test_a_fit_that_spoils_a_joint_without_a_fit_of_its_own_is_not_accepted() -> None:
    worse = _made_worse(coulomb_on(0), channels(1.4), fitted={0})
    assert worse == ["tau_3 1 -> 1.4 (noise 0.1)"]


def test_a_change_within_the_other_joints_noise_is_no_harm() -> None:
    assert _made_worse(coulomb_on(0), channels(1.05), fitted={0}) == []


def test_a_joint_with_its_own_fit_answers_for_its_own_channels() -> None:
    # joint 3 has a fit of its own: its worse torque is judged against that fit, not joint 1's
    assert _made_worse(coulomb_on(0), channels(1.4), fitted={0, 2}) == []
    assert _made_worse(coulomb_on(2), channels(1.4), fitted={0, 2}) == ["tau_3 1 -> 1.4 (noise 0.1)"]
