"""Sizes and stated 95 % intervals that hold: the misses of the concealed bench, each as a test
that failed before its fix (stiction sized ~15 % low; intervals from a split-half spread with
one degree of freedom that covered the truth about 70 % of the time)."""
from __future__ import annotations

import math

import numpy as np

from spacearm.offline.diagnosis.analysis import diagnose
from spacearm.offline.diagnosis.fitting import fit_features
from spacearm.offline.diagnosis.record import record_direct
from spacearm.offline.diagnosis.trajectory import Trajectory
from spacearm.firmware_sim.plant import load_plant_config

NOMINAL = load_plant_config("configs/plant/oru_testbed_nominal.toml")
Q_HOME = np.array([0.0, math.pi / 2, -math.pi / 2, 0.0, -math.pi / 2, 0.0])
DT = 0.02


def walk(joint: int, seconds: float = 40.0, seed: int = 11) -> Trajectory:
    """One joint on a smoothed random walk (many starts from near rest, both ways), the others still."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, DT)
    v = np.convolve(rng.normal(0, 1, len(t)), np.ones(150) / 150, mode="same")
    v *= 0.07 / float(np.max(np.abs(v)))
    q = np.repeat(Q_HOME[None, :], len(t), axis=0)
    q[:, joint] += np.cumsum(v) * DT
    return Trajectory(t, q)


def plant_with(joint: int, seed: int = 5, **effect):
    joints = [j.model_copy(update={"torque_noise": 0.5}) for j in NOMINAL.joints]
    joints[joint] = joints[joint].model_copy(update=effect)
    return NOMINAL.model_copy(update={"joints": joints, "seed": seed})


def test_stiction_is_sized_within_8_percent_and_its_interval_covers_it():
    truth = {"stribeck_friction": 4.6, "stribeck_velocity": 0.019}
    table = record_direct(plant_with(3, **truth), walk(3), None, hold_cycles=0)
    result = diagnose(table, NOMINAL)
    first = result.findings[0]
    assert first.fit.index == 3 and "stribeck" in first.fit.effects
    size, se = first.params["stribeck_friction"], first.stderr["stribeck_friction"]
    assert abs(size - 4.6) <= 0.08 * 4.6, size
    assert abs(size - 4.6) <= 1.96 * se, (size, se)


def test_stated_interval_holds_when_the_residual_wanders_slowly():
    """A friction-like column, fast correlated noise and a small slow disturbance (seconds
    long, as a slightly wrong model leaves; its autocorrelation is below 0.2 after a few
    rows, so a block length read off the autocorrelation misses it): the stated 95 %
    interval (1.96 standard errors) must cover the truth in at least 88 % of 200 draws
    (it was 77 %)."""
    rng = np.random.default_rng(2)
    n = 2000
    t = np.arange(n) * DT
    train = t < 0.6 * t[-1]
    covered = []
    for _ in range(200):
        x = np.sign(np.sin(2 * math.pi * t / rng.uniform(3.0, 6.0) + rng.uniform(0, 6.3)))
        slow = 0.3 * np.convolve(rng.normal(0, 1, n + 400), np.ones(400) / 20.0, mode="valid")[:n]
        fast, w = np.zeros(n), rng.normal(0, 0.5, n)
        for i in range(1, n):
            fast[i] = 0.5 * fast[i - 1] + w[i]
        y = 2.0 * x + slow * (1 + 0.5 * x) + fast
        fit = fit_features(("coulomb",), "tau", 0, ("coulomb_friction",), (np.nan,), x[:, None], y, train)
        covered.append(abs(fit.coef[0] - 2.0) <= 1.96 * fit.stderr[0])
    assert np.mean(covered) >= 0.88, np.mean(covered)


def test_a_light_joints_own_chatter_is_not_taken_for_a_ringing_gear():
    """A wrist joint at a constant 0.034 rad/s chatters (resolver steps times the servo gain)
    far above the median torque noise of the arm without any effect. With viscous drag it
    was named "elastic gear, the drive rings"; the friction (either law: one speed) must be
    named instead."""
    t = np.arange(0.0, 40.0, DT)
    q = np.repeat(Q_HOME[None, :], len(t), axis=0)
    q[:, 3] += 0.0341 * np.clip(t - 1.0, 0.0, None)
    table = record_direct(plant_with(3, seed=9, viscous_friction=110.0), Trajectory(t, q), None, hold_cycles=0)
    result = diagnose(table, NOMINAL)
    first = result.findings[0]
    assert first.fit.index == 3 and first.fit.effects[0] in ("coulomb", "viscous"), result.verdict


def test_backlash_interval_is_no_narrower_than_what_the_resolver_resolves():
    """Play is read through the link resolver (25 arcsec steps): its stated interval was as
    narrow as +-0.5 % and missed a truth 1.6 % away on the concealed bench."""
    from spacearm.firmware_sim.plant import ARCSEC
    t = np.arange(0.0, 25.0, DT)
    sway = Trajectory(t, Q_HOME + 0.1 * np.sin(2 * math.pi * t[:, None] / np.array([5, 6, 7, 8, 9, 10])))
    table = record_direct(plant_with(5, seed=4, backlash=2.9e-3), sway, None, hold_cycles=0)
    first = diagnose(table, NOMINAL).findings[0]
    assert first.fit.effects == ("backlash",) and first.fit.index == 5
    step = NOMINAL.joints[5].resolver_arcsec * ARCSEC
    assert first.stderr["backlash"] >= step / math.sqrt(12.0) * 0.999     # it was 8e-6 rad (0.3 %)
    assert abs(first.params["backlash"] - 2.9e-3) <= 1.96 * first.stderr["backlash"]


def test_wide_play_is_sized_from_how_far_the_link_wanders():
    """4 mrad of play on the light wrist joint: the hunting torque is no larger than with
    2.8 mrad (the drive limits it), so a size found on the torque envelope stopped at 2.8
    (32 % low, interval missed). The link position wanders through the play."""
    truth = 4.1e-3
    table = record_direct(plant_with(5, seed=4, backlash=truth), walk(5), None, hold_cycles=0)
    first = diagnose(table, NOMINAL).findings[0]
    assert first.fit.effects == ("backlash",) and first.fit.index == 5
    fitted, half = first.params["backlash"], 1.96 * first.stderr["backlash"]
    print(f"backlash true {truth:.4g} fitted {fitted:.4g} +- {half:.2g}")
    assert abs(fitted - truth) <= 0.15 * truth
    assert abs(fitted - truth) <= half


def test_large_stiction_is_sized_with_its_decay_speed_by_replay():
    """22.8 N m of stiction: the joint sticks and slips, and the linear fit traded level for a
    slower decay (12.5 +- 1.9 N m fading above 0.024 rad/s). Replays of the joint with both
    found together size it, and the interval holds."""
    truth = {"stribeck_friction": 22.8, "stribeck_velocity": 0.0159}
    table = record_direct(plant_with(1, **truth), walk(1), None, hold_cycles=0)
    first = diagnose(table, NOMINAL).findings[0]
    assert first.fit.effects == ("stribeck",) and first.fit.index == 1
    fitted, half = first.params["stribeck_friction"], 1.96 * first.stderr["stribeck_friction"]
    print(f"stiction true 22.8 fitted {fitted:.4g} +- {half:.2g}, decay {first.params['stribeck_velocity']:.3g}")
    assert abs(fitted - 22.8) <= 0.15 * 22.8
    assert abs(fitted - 22.8) <= half


def test_stick_slip_stiction_is_read_from_the_breakaway_torque():
    """27 N m of stiction fading above 0.01 rad/s: the joint sticks and slips, and the replays
    preferred a lower level with a slower decay (about 10 N m). At each start from rest the
    drive's torque peaks at the level before the joint breaks free; read there (and confirmed
    by the held-out starts), the size and its interval hold."""
    table = record_direct(plant_with(4, stribeck_friction=27.0, stribeck_velocity=0.010), walk(4), None,
                          hold_cycles=0)
    first = diagnose(table, NOMINAL).findings[0]
    assert first.fit.effects == ("stribeck",) and first.fit.index == 4
    fitted, half = first.params["stribeck_friction"], 1.96 * first.stderr["stribeck_friction"]
    print(f"stiction true 27 fitted {fitted:.4g} +- {half:.2g} ({first.fit.judged_by})")
    assert first.fit.judged_by == "breakaway"
    assert abs(fitted - 27.0) <= 0.15 * 27.0 and abs(fitted - 27.0) <= half


def test_a_shape_the_fitting_rows_do_not_excite_is_refused_not_blown_up():
    """Stribeck's narrow bump only where the held-out rows start the joint: on the fitting rows
    the column is ~1e-300, and a least-squares coefficient of 1e281 overflowed the held-out RMS."""
    import warnings
    x = np.zeros((80, 1))
    x[60:, 0] = 0.5
    x[:40, 0] = 1e-300
    y = np.sin(np.arange(80.0))
    train = np.arange(80) < 40
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        fit = fit_features(("stribeck",), "tau", 0, ("stribeck_friction",), (0.0025,), x, y, train)
    assert fit.sse_train == math.inf and fit.p_value == 1.0 and np.all(fit.coef == 0.0)
    assert math.isfinite(fit.rms_heldout_after) and fit.rms_heldout_after == fit.rms_heldout_before
