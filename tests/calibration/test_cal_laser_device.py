"""Simulated laser ranger on a pty and its pyserial driver."""
from __future__ import annotations

import os

import numpy as np
import pytest

from spacearm.drivers.laser_ranger import LaserRanger, NoHit, RangerError
from spacearm.base.laser_ranger_protocol import checksum, frame, parse_frame
from spacearm.firmware_sim.laser_ranger import LaserRangerSim, RangerConfig


def test_frame_round_trip_and_checksum_rejection():
    f = frame("D,1234.567")
    assert parse_frame(f) == "D,1234.567"
    bad = f.replace(b"1234", b"1235")
    assert parse_frame(bad) is None
    assert parse_frame(b"garbage\r\n") is None
    assert checksum(b"MEAS") == (ord("M") ^ ord("E") ^ ord("A") ^ ord("S"))


def test_measure_noise_and_info():
    with LaserRangerSim(lambda: 1.2345, RangerConfig(seed=1)) as sim, LaserRanger(sim.port) as dev:
        assert dev.ping()
        info = dev.info()
        assert info.sigma == pytest.approx(0.2e-3) and info.max_range == pytest.approx(5.0)
        xs = np.array([dev.measure() for _ in range(40)])
        assert abs(xs.mean() - 1.2345) < 4 * 0.2e-3 / np.sqrt(40)
        assert 0.1e-3 < xs.std() < 0.35e-3
        assert abs(dev.average(10) - 1.2345) < 0.5e-3


@pytest.mark.parametrize("distance", [None, 7.0, 0.01])
def test_invalid_readings_raise_nohit(distance):
    with LaserRangerSim(lambda: distance) as sim, LaserRanger(sim.port) as dev:
        with pytest.raises(NoHit):
            dev.measure()


def test_garbled_replies_are_rejected_and_retried():
    cfg = RangerConfig(garble_prob=0.5, seed=3)
    with LaserRangerSim(lambda: 2.0, cfg) as sim, LaserRanger(sim.port, retries=10) as dev:
        xs = [dev.measure() for _ in range(20)]
        assert dev.rejected > 0
        assert all(abs(x - 2.0) < 2e-3 for x in xs)


def test_silent_device_times_out():
    cfg = RangerConfig(drop_prob=1.0)
    with LaserRangerSim(lambda: 2.0, cfg) as sim, LaserRanger(sim.port, timeout=0.05, retries=2) as dev:
        with pytest.raises(RangerError, match="3 attempts"):
            dev.measure()
        assert sim.requests == 3


def test_bad_request_checksum_gets_error_reply():
    with LaserRangerSim(lambda: 2.0) as sim:
        fd = os.open(sim.port, os.O_RDWR | os.O_NOCTTY)
        try:
            os.write(fd, b"$MEAS*00\r\n")
            import select
            select.select([fd], [], [], 1.0)
            assert parse_frame(os.read(fd, 64)) == "E,BADCS"
        finally:
            os.close(fd)


def test_end_to_end_identification_through_the_serial_device(laser_setup):
    """Readings through the pty driver feed the identification: pose error shrinks ~100x."""
    from spacearm.controller.calibration import compare_poses, lm
    from spacearm.controller.calibration.study_laser import candidates
    from spacearm.firmware_sim.laser_ranger import arm_plane_distance
    st = laser_setup
    Q = candidates(st, 60, np.random.default_rng(12))
    current = {"q": Q[0]}
    plane_true = st.x_true[st.model.n_params:]
    src = arm_plane_distance(st.model, st.x_true, plane_true[:3], plane_true[3], lambda: current["q"])
    with LaserRangerSim(src, RangerConfig(seed=5)) as sim, LaserRanger(sim.port) as dev:
        h = []
        for q in Q:
            current["q"] = q
            h.append(dev.average(4))
    res = lm(st.problem(Q, np.array(h), 0.2e-3 / 2))
    Qv = st.model.kin.random_configurations(20, np.random.default_rng(13))
    T_true = st.model.poses(st.x_true, Qv)
    before = compare_poses(T_true, st.model.poses(st.model.nominal, Qv)).rms_pos.max()
    after = compare_poses(T_true, st.model.poses(res.x[: st.model.n_params], Qv)).rms_pos.max()
    assert after < before / 30
