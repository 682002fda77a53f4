"""Play and a soft gear both make the drive hunt. Where their simulated envelopes fit the
recording alike, the finding names both, with the signatures and the experiment that tells
them apart (a stiffness of 5e4 N m/rad was named "backlash 2.5 +- 1 mrad" with no alternative)."""
from __future__ import annotations

import numpy as np

from spacearm.offline.diagnosis.analysis import GEAR_EXPERIMENT, _why_alike, gear_alternatives
from spacearm.offline.diagnosis.fitting import ChannelFit


def gear(effect: str, key: str, value: float, envelope_error: float) -> ChannelFit:
    return ChannelFit((effect,), "tau", 3, np.array([value]), np.array([0.1 * value]), (key,), (float("nan"),),
                      1.0, 10.0, 4.0, envelope_error, 0.0, 25)


def test_a_soft_gear_that_fits_as_well_as_play_is_named_beside_it() -> None:
    play, soft = gear("backlash", "backlash", 2.5e-3, 1.0), gear("elasticity", "joint_stiffness", 5e4, 1.1)
    assert gear_alternatives(play, [play, soft]) == [soft]
    why = _why_alike(np.sin(np.linspace(0, 20, 500)), "revolute", play, soft)
    assert why == GEAR_EXPERIMENT and "dead band" in why and "grows with the load" in why


def test_a_clearly_worse_gear_fit_is_no_alternative() -> None:
    play, soft = gear("backlash", "backlash", 2.5e-3, 1.0), gear("elasticity", "joint_stiffness", 5e4, 2.0)
    assert gear_alternatives(play, [play, soft]) == []
    # a friction law chosen over both: the gear fits are no alternatives to it
    assert gear_alternatives(gear("coulomb", "coulomb_friction", 2.0, 0.5), [play, soft]) == []
