"""The simulator's compiled core (firmware_sim/_simcore.c, built by setup.py when a C compiler
is there), or None: without it, or with SPACEARM_PURE_PYTHON=1 in the environment, every caller
runs its Python path, which computes the same bits (tests/firmware_sim/test_simcore.py)."""
from __future__ import annotations

import os

SERVO_OFF, SERVO_CSP = 0, 1    # the servo laws the compiled core runs (_simcore.c)

core = None
if os.environ.get("SPACEARM_PURE_PYTHON", "") in ("", "0"):
    try:
        from spacearm.firmware_sim import _simcore as core
    except ImportError:       # not built (no compiler at install time): the Python path
        core = None
