"""What a diagnosis costs is replays. Two savings that must not change an answer: a per-joint
replay skips the F/T channel it never reads, and the re-simulation with the fits replays only
the fitted joints (the others are the nominal replay's columns)."""
from __future__ import annotations

import math

import numpy as np

from spacearm.firmware_sim.plant import load_plant_config
from spacearm.offline.diagnosis.direct_sim import SimTraces, simulate
from spacearm.offline.diagnosis.fitting import ChannelFit

NOMINAL = load_plant_config("configs/plant/oru_testbed_nominal.toml")


def _commands(rows: int = 150) -> np.ndarray:
    t = np.arange(rows) * 0.02
    q = np.zeros((rows, 6))
    q[:, 2] = 0.05 * np.sin(2 * math.pi * 0.5 * t)
    return q


def test_a_replay_without_the_ft_channel_gives_the_same_joint_traces() -> None:
    noisy = NOMINAL.model_copy(update={"seed": 11, "ft": NOMINAL.ft.model_copy(update={"noise_force": 0.3})})
    full = simulate(noisy, _commands(), 0.02, joints=[2])
    lean = simulate(noisy, _commands(), 0.02, joints=[2], wrench=False)
    for name in ("q", "dq", "tau"):
        assert np.array_equal(getattr(full, name), getattr(lean, name)), name
    assert not np.any(lean.wrench) and np.any(full.wrench)


def _fit(effect: str, channel: str, index: int, column: str, value: float) -> ChannelFit:
    return ChannelFit((effect,), channel, index, np.array([value]), np.array([0.1 * value]), (column,),
                      (float("nan"),), 1.0, 10.0, 2.0, 1.0, 0.0, 1)


def test_the_refit_replays_only_the_fitted_joints_and_matches_a_full_replay(monkeypatch) -> None:
    from spacearm.offline.diagnosis import analysis
    from spacearm.offline.diagnosis.fit_parameters import apply_fits
    from spacearm.offline.diagnosis.record import record_direct
    from spacearm.offline.diagnosis.trajectory import Trajectory

    commands = _commands() + 0.02 * np.sin(np.arange(150) * 0.1)[:, None]
    table = record_direct(NOMINAL, Trajectory(np.arange(150) * 0.02, commands), None, hold_cycles=0)
    sim = analysis.replay(table, NOMINAL)
    fits = [_fit("coulomb", "tau", 2, "coulomb_friction", 3.0), _fit("ft_bias", "wrench", 1, "bias", 0.5)]
    full = analysis.replay(table, apply_fits(NOMINAL, fits))
    simulated = []
    real_simulate = analysis.simulate
    monkeypatch.setattr(analysis, "simulate", lambda *a, **k: simulated.append(k.get("joints")) or
                        real_simulate(*a, **k))
    _, refit = analysis._stable_refit(table, NOMINAL, list(fits), sim, replayed=True)
    assert simulated == [[2]]
    for name in ("q", "dq", "tau", "wrench"):
        assert np.array_equal(getattr(refit, name), getattr(full, name)), name


def _own_paths(monkeypatch) -> None:
    """The plant's own sub-step-by-sub-step Python paths: no compiled core, and no servo law for
    a whole period (so no two-mass period either)."""
    from spacearm.firmware_sim import simcore
    from spacearm.offline.diagnosis import direct_sim
    monkeypatch.setattr(simcore, "core", None)
    monkeypatch.setattr(direct_sim._CspDrive, "_period_law", lambda self: None)


def test_the_fast_replay_paths_give_the_plants_own_bits(monkeypatch) -> None:
    """The compiled core's rigid-gear period and the plant's two-mass period (a loose, elastic,
    rubbing gear with transmission error, torque noise and feedback latency) replay exactly
    what the plant's own Python path replays."""
    commands = _commands(400) + 0.002 * (np.arange(400) % 37 == 0)[:, None]
    joints = list(NOMINAL.joints)
    joints[2] = joints[2].model_copy(update={"backlash": 1e-3, "joint_stiffness": 4e4, "coulomb_friction": 3.0,
                                             "stribeck_friction": 2.0, "stribeck_velocity": 0.01,
                                             "te_amplitude": 1e-4, "te_harmonic": 2.0, "torque_noise": 0.5,
                                             "feedback_latency_cycles": 2})
    joints[4] = joints[4].model_copy(update={"joint_stiffness": 2e5, "gravity_torque": 5.0})
    plant = NOMINAL.model_copy(update={"joints": joints, "seed": 4})
    fast = [simulate(plant, commands, 0.02), simulate(plant, commands, 0.02, joints=[2], wrench=False)]
    _own_paths(monkeypatch)
    own = [simulate(plant, commands, 0.02), simulate(plant, commands, 0.02, joints=[2], wrench=False)]
    for a, b in zip(fast, own):
        for name in ("q", "dq", "tau", "wrench"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name
        assert a.following_error_max == b.following_error_max
