"""The simulator's compiled core switched on or off inside a test, to compare the two paths."""
from __future__ import annotations

from contextlib import contextmanager

import pytest

from spacearm.firmware_sim import simcore

needs_core = pytest.mark.skipif(simcore.core is None, reason="compiled core not built (no C compiler at install "
                                                              "time) or SPACEARM_PURE_PYTHON=1: nothing to compare")


@contextmanager
def core_switched(on: bool):
    """The core as built (on) or the pure-Python path (off) for what runs inside."""
    saved, simcore.core = simcore.core, simcore.core if on else None
    try:
        yield
    finally:
        simcore.core = saved
