"""The rest-to-rest quintic time law s(tau) (ORU paper, Section 4.1, eq. 2), on its own so that
a user of the time law alone (the ORU flow's straight tool moves) does not import scipy's
rotations with the Cartesian path: in a campaign worker that import was ~0.2 s of its start."""
from __future__ import annotations

import math

# Peak of ds/dt and d2s/dt2 for s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5 on tau in [0, 1].
QUINTIC_PEAK_VELOCITY = 1.875
QUINTIC_PEAK_ACCELERATION = 10.0 / math.sqrt(3.0)


def quintic(tau: float) -> tuple[float, float, float]:
    """s, ds/dtau, d2s/dtau2 of the rest-to-rest quintic at tau in [0, 1]."""
    tau = min(max(tau, 0.0), 1.0)
    s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
    ds = 30.0 * tau**2 * (1.0 - tau) ** 2
    dds = 60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau)
    return s, ds, dds
