"""Laser ranger faults over its serial line (a pty served by the simulator's ranger): a dead
ranger or one that answers garbage gives a RangerError within a bounded time (timeout x
attempts), never a hang or a wrong distance; light garbling is retried and still reads right.
The calibration routine stops on that error with the arm holding (it commands no motion of
its own between readings)."""
from __future__ import annotations

import time

import pytest

from spacearm.drivers.laser_ranger import LaserRanger, RangerError
from spacearm.firmware_sim.laser_ranger import LaserRangerSim, RangerConfig

pytestmark = pytest.mark.hil
DISTANCE = 0.75


def ranger(**config) -> LaserRangerSim:
    return LaserRangerSim(lambda: DISTANCE, RangerConfig(sigma=0.0, **config))


def test_laser_ranger_timeout_raises_within_bounded_time():
    with ranger(drop_prob=1.0) as sim, LaserRanger(sim.port, timeout=0.1, retries=2) as dev:
        t0 = time.monotonic()
        with pytest.raises(RangerError, match="timeout"):
            dev.measure()
        elapsed = time.monotonic() - t0
    assert elapsed < 3 * 0.1 * 3 + 0.5, elapsed      # (retries+1) transactions per attempt, bounded


def test_laser_ranger_garbage_is_rejected_then_raises():
    with ranger(garble_prob=1.0) as sim, LaserRanger(sim.port, timeout=0.1, retries=2) as dev:
        with pytest.raises(RangerError, match="garbled|unexpected|malformed"):
            dev.measure()
        assert dev.rejected >= 3


def test_laser_ranger_light_garbling_is_retried_and_reads_right():
    with ranger(garble_prob=0.2, drop_prob=0.1, seed=3) as sim, LaserRanger(sim.port, timeout=0.1, retries=4) as dev:
        values = [dev.measure() for _ in range(20)]
    assert values == pytest.approx([DISTANCE] * 20, abs=1e-6)
