"""Sim-vs-real diagnosis on a NEW concealed set: own trajectories and effect draws (not the
seeds or trajectory kinds of bench_diagnosis.py), 6- and 7-joint arms (the 7-joint arm's
joint 1 is a prismatic linear rail), sensor effects, out-of-catalogue effects and
effect-free recordings, direct and made in real time; scored against the issue's targets.

    .venv/bin/python bench/bench_diagnosis_concealed.py [--cases 30] [--duration 40] [--seed 7001]
        [--realtime 2] [--no-timing] [--families new] [--jobs 2] [--effects gravity_load,coulomb]

--jobs N runs the cases in N worker processes (the draws stay in order in this one, so a seed
gives the same cases for any N); each case's whole time (recording, reference replays,
diagnosis, score) is printed beside the diagnosis time.

--families new draws trajectories from families the diagnosis was never tuned on (Swevers
et al.'s Fourier-series excitation, the real Panda recording's motions, slow ramps,
point-to-point moves); report those figures on a held-out seed (9001 and up), never tune on it.

The timing row diagnoses one 60 s 7-joint recording of every trajectory family (old and new)
and is judged on the slowest; --no-timing leaves it out.

Run it on a second seed (--seed 7002) to see that the figures hold beyond the one case set.
Shares are printed with their 95 % Wilson interval [low-high].

Trajectories: chirps (frequency sweeps, both ways), smoothed random walks, triangle waves
at two speeds, constant-speed one-way ramps. Effects (one per case, two every fifth):
Coulomb, viscous, Stribeck, load, position-feedback latency, backlash, F/T bias/drift from
the catalogue; velocity-channel lag and encoder / torque-sensor quantisation (applied to the
recording, as a logger or sensor would); out of the catalogue: cogging torque (sin 30 q),
a periodic 0.7 Hz disturbance, a torque step half-way.

Arms: the ORU test bed (6 joints) and, every other case, the test bed on a linear rail: a
7-joint arm whose joint 1 is prismatic (50 kg carriage and arm on a 10 mm lead ball screw,
1 um linear encoder; its position in m, its force in N) and whose joint 7 is a second wrist
joint. Effects on the rail and on joint 7 are sized against their own channel's noise
(N, N s/m on the rail). The random draws of the 7-joint cases are those of the bench before
the rail (same seed, same trajectories and effect draws); which effects move to the rail is
drawn from a separate generator, so the revolute cases are unchanged.

Effect-free recordings: the direct path, and `--realtime N` recordings made through the
daemon on its real-time clock over CAN (6 joints, jitter and skipped cycles). The
diagnosis reads only the CSV; the scorer alone reads the truth.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib.util
import math
import multiprocessing
import os
import platform
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
_spec = importlib.util.spec_from_file_location("bench_diagnosis", ROOT / "bench" / "bench_diagnosis.py")
base = importlib.util.module_from_spec(_spec)
sys.modules["bench_diagnosis"] = base
_spec.loader.exec_module(base)

from spacearm.offline.diagnosis.analysis import diagnose  # noqa: E402
from spacearm.offline.diagnosis.direct_sim import SimulationDiverged, simulate  # noqa: E402
from spacearm.offline.diagnosis.honesty import one_way, single_speed  # noqa: E402
from spacearm.offline.diagnosis.physical import parameter_violations  # noqa: E402
from spacearm.offline.diagnosis.record import record_direct  # noqa: E402
from spacearm.offline.diagnosis.recording_io import read_table, write_csv  # noqa: E402
from spacearm.offline.diagnosis.report import write_report  # noqa: E402
from spacearm.offline.diagnosis.trajectory import Trajectory  # noqa: E402
from spacearm.firmware_sim.plant import PlantConfig, load_plant_config  # noqa: E402

DT = base.DT
VMAX = base.VMAX
PLANT_EFFECTS = ("coulomb", "viscous", "stribeck", "gravity_load", "latency", "backlash", "elasticity", "ft_bias",
                 "ft_drift")
SENSOR_EFFECTS = ("velocity_latency", "position_quantisation", "torque_quantisation")
OUT_OF_CATALOGUE = ("cogging", "periodic", "torque_step")
CI_Z = 1.96
HELD_OUT = 9001      # seeds from here on: the reported figure only; develop on seeds below
VISIBLE = 3.0        # effect sizes drawn 1.5 .. 30x the channel noise (bench_diagnosis.py covers 0.5 .. 10x)
# The 7-joint arm's joint 1: the test bed on a linear rail. 50 kg moving (a 20 kg carriage and
# the ~30 kg arm) on a ball screw of 10 mm lead (2 pi / 0.01 = 628 motor rad per m); the
# default motor (3e-4 kg m^2) adds 118 kg reflected through the screw.
RAIL_SCREW = 2 * math.pi / 0.01
RAIL = {"kind": "prismatic", "link_inertia": 50.0, "gear_ratio": RAIL_SCREW, "initial_position": 0.0}
RAIL_SHARE = 0.4     # of the 7-joint cases' joint effects not on joint 7: moved to the rail


def home(n: int) -> np.ndarray:
    return np.concatenate([base.Q_HOME, [0.3]])[:n]


# Families the diagnosis was not tuned on (--families new): Swevers et al.'s periodic excitation
# (a finite Fourier series per joint, IEEE T-RA 1997), the real Panda recording's own exciting
# trajectory (Gaz et al. RA-L 2019, ../shared/data/panda_gaz2019; its joint motions, rescaled to
# this arm's speed), slow ramps back and forth, and point-to-point moves with dwells.
NEW_FAMILIES = ("fourier", "panda", "slow_ramp", "point_to_point")
PANDA = ROOT.parent / "shared" / "data" / "panda_gaz2019" / "exciting_traj_1.csv"


def _panda_motion(rng: np.random.Generator, t: np.ndarray, n: int) -> np.ndarray:
    """The Panda's recorded joint motions (a random joint and start for each of ours), scaled so
    the fastest speed is 0.5 x this arm's; centred on zero. A case longer than the recording
    (21 s) plays it back the other way from its end (played forward again from its start, each
    joint jumped by up to 2.8 rad in one row: that jump set the speed scale, and every Panda
    case moved its joint 2-25 mrad in all, 2.4 of them in that one row)."""
    data = np.loadtxt(PANDA, delimiter=",", skiprows=1, usecols=range(8))
    src_t, src_q = data[:, 0], data[:, 1:8]
    keep = np.r_[True, np.diff(src_t) > 0]
    src_t, src_q = src_t[keep], src_q[keep]
    out = np.empty((len(t), n))
    for j in range(n):
        col = src_q[:, int(rng.integers(0, 7))]
        start = rng.uniform(0.0, max(src_t[-1] - t[-1], 0.0))
        phase = (start + t) % (2 * src_t[-1])
        x = np.interp(np.where(phase <= src_t[-1], phase, 2 * src_t[-1] - phase), src_t, col)
        v = np.max(np.abs(np.gradient(x, t[1] - t[0])))
        out[:, j] = (x - x.mean()) * 0.5 * VMAX / max(v, 1e-9)
    return out


def _new_family_motion(kind: str, rng: np.random.Generator, t: np.ndarray, duration: float) -> np.ndarray:
    if kind == "fourier":
        wf = 2 * math.pi / rng.uniform(8.0, 14.0)
        harmonics = np.arange(1, 6)
        a, b = rng.normal(0, 1, 5), rng.normal(0, 1, 5)
        x = sum(a[l - 1] / (wf * l) * np.sin(wf * l * t) - b[l - 1] / (wf * l) * np.cos(wf * l * t) for l in harmonics)
        x = x - x[0]
        return x * 0.5 * VMAX / max(float(np.max(np.abs(np.gradient(x, DT)))), 1e-9)
    if kind == "slow_ramp":
        speed = rng.uniform(0.03, 0.12) * VMAX
        period = rng.uniform(8.0, 16.0)
        return speed * period / 4 * (2 / math.pi) * np.arcsin(np.sin(2 * math.pi * t / period))
    # point to point: smooth (cosine) moves to random targets with dwells between them
    x, out, k = 0.0, np.zeros(len(t)), 0
    while k < len(t):
        target = rng.uniform(-0.15, 0.15)
        move = max(int(abs(target - x) / (0.4 * VMAX) * math.pi / 2 / DT), 5)
        dwell = int(rng.uniform(0.5, 2.0) / DT)
        s = 0.5 - 0.5 * np.cos(np.linspace(0.0, math.pi, move))
        seg = np.r_[x + (target - x) * s, np.full(dwell, target)]
        out[k:k + len(seg)] = seg[: len(t) - k]
        k += len(seg)
        x = target
    return out


def trajectory(rng: np.random.Generator, n: int, duration: float, families: tuple[str, ...] | None = None
               ) -> tuple[str, Trajectory]:
    t = np.arange(0.0, duration, DT)
    if families:
        kind = str(rng.choice(list(families)))
    else:
        kind = str(rng.choice(["chirp", "walk", "two_speeds", "ramp"], p=[0.35, 0.3, 0.2, 0.15]))
    q = np.repeat((home(n) + rng.uniform(-0.03, 0.03, n))[None, :], len(t), axis=0)
    if kind == "panda":
        return kind, Trajectory(t, q + _panda_motion(rng, t, n))
    for j in range(n):
        if kind in NEW_FAMILIES:
            q[:, j] += _new_family_motion(kind, rng, t, duration)
        elif kind == "chirp":
            f0, f1 = rng.uniform(0.03, 0.08), rng.uniform(0.15, 0.3)
            phase = 2 * math.pi * (f0 * t + 0.5 * (f1 - f0) * t ** 2 / duration)
            amp = 0.5 * VMAX / (2 * math.pi * f1)
            q[:, j] += amp * np.sin(phase + rng.uniform(0, 2 * math.pi))
        elif kind == "walk":
            v = np.convolve(rng.normal(0, 1, len(t)), np.ones(150) / 150, mode="same")
            v *= 0.6 * VMAX / max(float(np.max(np.abs(v))), 1e-9)
            q[:, j] += np.cumsum(v) * DT
        elif kind == "two_speeds":
            speed = rng.uniform(0.2, 0.5) * VMAX
            phase = np.cumsum(np.where(t < duration / 2, speed, 2.5 * speed)) * DT / 0.15   # continuous
            q[:, j] += np.abs((phase % 2.0) - 1.0) * 0.15
        else:
            q[:, j] += rng.uniform(0.1, 0.5) * VMAX * rng.choice([-1, 1]) * t
    return kind, Trajectory(t, q)


def with_joints(config: PlantConfig, n: int, seed: int, noise: bool = True) -> PlantConfig:
    """The arm's plant (see nominal_for) with sensor noise: 0.5 N m (N on the rail) rms torque."""
    config = nominal_for(config, n)
    joints = [config.joints[i].model_copy(update={"torque_noise": 0.5 if noise else 0.0}) for i in range(n)]
    return config.model_copy(update={"joints": joints, "seed": seed, "ft": config.ft.model_copy(
        update={"noise_force": 0.3 if noise else 0.0, "noise_torque": 0.01 if noise else 0.0})})


def nominal_for(nominal: PlantConfig, n: int) -> PlantConfig:
    """The nominal plant of an n-joint arm: a 7-joint arm's seventh joint is a second wrist
    joint (the plant file's last joint), and its joint 1 the linear rail, in the nominal as in
    the truth (a plant already on the rail is kept as it is)."""
    joints = [nominal.joints[i] if i < len(nominal.joints) else nominal.joints[-1] for i in range(n)]
    if n == 7 and not joints[0].prismatic:
        joints[0] = type(joints[0])(**RAIL)
    return nominal.model_copy(update={"joints": joints})


def channel_noise(nominal: PlantConfig, n: int, traj: Trajectory, seed: int) -> dict[str, float]:
    """The noise the tool will see on each channel for this trajectory: an effect-free noisy
    recording minus the nominal replay, row-to-row scatter. Effect sizes are drawn against it."""
    from spacearm.offline.diagnosis.analysis import noise_level
    table = record_direct(with_joints(nominal, n, seed), traj, None, hold_cycles=0)
    sim = simulate(nominal_for(nominal, n), table.q_cmd, table.dt, q0=table.q[0])
    out = {f"tau_{j + 1}": noise_level(table.tau[:, j] - sim.tau[:, j]) for j in range(n)}
    out |= {c: noise_level(table.wrench[:, i] - sim.wrench[:, i]) for i, c in enumerate(base.WRENCH_COLUMNS)}
    return out


def draw(rng, kind: str, n: int, traj: Trajectory, duration: float, noise: dict[str, float],
         rail_rng: np.random.Generator | None = None) -> list[dict]:
    """The truths of one case (dicts: effect, index, params, channel). `rail_rng` decides which
    joint effects of a 7-joint case move to the rail (joint 1), apart from `rng` so that the
    case's other draws stay those of the bench before the rail."""
    if kind == "none":
        return []
    if kind == "sensor":
        effect, j = str(rng.choice(SENSOR_EFFECTS)), int(rng.integers(0, n))
        p = {"velocity_latency": {"velocity_latency_cycles": int(rng.integers(1, 4))},
             "position_quantisation": {"quantum": float(rng.uniform(4e-4, 2e-3))},
             "torque_quantisation": {"quantum": float(rng.uniform(1.0, 4.0))}}[effect]
        if n == 7 and j == 0 and effect == "torque_quantisation":
            # the rail's own force sensor: its 6077h step is the screw's ratio coarser (N, not N m)
            p["quantum"] *= RAIL_SCREW / 100.0
        return [{"effect": effect, "index": j, "params": p, "channel": "dq" if "velocity" in effect else
                 "q" if "position" in effect else "tau"}]
    if kind == "ooc":
        effect, j = str(rng.choice(OUT_OF_CATALOGUE)), int(rng.integers(0, n))
        return [{"effect": effect, "index": j, "params": {"size": float(rng.uniform(3.0, 8.0))}, "channel": "tau"}]
    count = 2 if kind == "two" else 1
    effects = list(rng.choice(PLANT_EFFECTS, size=count, replace=False))
    used: set = set()
    out = []
    for e in effects:
        tr = base.draw_effect(rng, e, used, duration, Trajectory(traj.t, traj.q[:, :6]),
                              {k: VISIBLE * v for k, v in noise.items()})
        if e not in base.FT_EFFECTS and n == 7 and rng.random() < 0.4 and ("joint", 6) not in used:
            # the seventh joint gets its share of the effects, sized against its own noise
            used.add(("joint", 6))
            resize(tr, 6, noise, traj)
        elif e not in base.FT_EFFECTS and n == 7 and rail_rng is not None and tr.index != 0 and \
                ("joint", 0) not in used and rail_rng.random() < RAIL_SHARE:
            # ... and so does the rail, in N and N s/m against its own noise
            used.add(("joint", 0))
            resize(tr, 0, noise, traj)
        out.append({"effect": tr.effect, "index": tr.index, "params": tr.params, "channel": tr.channel})
    return out


def resize(tr, to: int, noise: dict[str, float], traj: Trajectory) -> None:
    """Move a drawn joint effect to joint `to`, its size scaled from its joint's noise to the
    new joint's (and, for viscous friction, from its speeds to the new joint's)."""
    scale = noise[f"tau_{to + 1}"] / noise[f"tau_{tr.index + 1}"]
    for key in ("coulomb_friction", "stribeck_friction", "gravity_torque"):
        if key in tr.params:
            tr.params[key] *= scale
    if "viscous_friction" in tr.params:
        v = lambda j: max(float(np.sqrt(np.mean(np.gradient(traj.q[:, j], DT) ** 2))), 0.01)
        tr.params["viscous_friction"] *= scale * v(tr.index) / v(to)
    tr.index = to


def apply_plant(config: PlantConfig, truths: list[dict]) -> PlantConfig:
    joints, ft = list(config.joints), config.ft
    bias, drift = list(ft.bias), list(ft.drift)
    for tr in truths:
        if tr["effect"] == "ft_bias":
            bias[tr["index"]] += tr["params"]["bias"]
        elif tr["effect"] == "ft_drift":
            drift[tr["index"]] += tr["params"]["drift"]
        elif tr["effect"] in PLANT_EFFECTS:
            joints[tr["index"]] = joints[tr["index"]].model_copy(update=tr["params"])
    return config.model_copy(update={"joints": joints, "ft": ft.model_copy(update={"bias": tuple(bias),
                                                                                   "drift": tuple(drift)})})


def apply_recording(table, truths: list[dict]) -> None:
    """Effects that live in the sensors or outside the catalogue, applied to the recording."""
    t = table.t - table.t[0]
    for tr in truths:
        j, e, p = tr["index"], tr["effect"], tr["params"]
        if e == "velocity_latency":
            k = p["velocity_latency_cycles"]
            table.dq[k:, j] = table.dq[:-k, j].copy()
        elif e == "position_quantisation":
            table.q[:, j] = np.round(table.q[:, j] / p["quantum"]) * p["quantum"]
        elif e == "torque_quantisation":
            table.tau[:, j] = np.round(table.tau[:, j] / p["quantum"]) * p["quantum"]
        elif e == "cogging":
            table.tau[:, j] += p["size"] * np.sin(30.0 * table.q[:, j])
        elif e == "periodic":
            table.tau[:, j] += p["size"] * np.sin(2 * math.pi * 0.7 * t)
        elif e == "torque_step":
            table.tau[:, j] += np.where(t > 0.5 * t[-1], p["size"], 0.0)


def sensor_visibility(before: np.ndarray, after: np.ndarray) -> float:
    """How far a sensor effect moved its channel, over the channel's white noise (second
    differences: a smooth motion hardly has any, so a lag of one cycle on a smooth velocity
    counts as visible and a lag on a constant speed does not)."""
    noise = float(np.std(np.diff(before, 2))) / math.sqrt(6.0) + 1e-12
    return float(np.sqrt(np.mean((after - before) ** 2))) / noise


def matches(f: dict, tr: dict) -> bool:
    if tr["effect"] not in f["effects"]:
        return False
    if tr["effect"] in base.FT_EFFECTS:
        return f["axis"] == tr["index"]
    return f["joint"] == tr["index"] + 1


def score(summary: dict, truth: dict, ceiling: dict[str, float]) -> dict:
    truths, findings = truth["truths"], summary["findings"]
    s = {"name": truth["name"], "kind": truth["kind"], "n": truth["n"], "effects": [t["effect"] for t in truths],
         "named": False, "alarm": bool(findings or summary["unexplained_channels"] or summary["sensor_findings"]),
         "param_ok": [], "ci_ok": [], "ci_miss": [], "reduction": [], "ceiling": [], "ambiguous": False,
         "answer": summary["verdict"][:240], "units": [f["unit"] for f in findings if f["joint"] == 1],
         "truth": "; ".join(f"{t['effect']} joint/axis {t['index'] + 1} {t['params']}" for t in truths)}
    if truth["kind"] == "none":
        return s
    if truth["kind"] == "sensor":
        tr = truths[0]
        s["named"] = any(f["effect"] == tr["effect"] and f["joint"] == tr["index"] + 1
                         for f in summary["sensor_findings"])
        return s
    if truth["kind"] == "ooc":
        tr = truths[0]
        s["named"] = f"tau_{tr['index'] + 1}" in summary["unexplained_channels"]
        return s
    top = findings[:len(truths)]
    s["named_each"] = {t["effect"]: any(matches(f, t) for f in top) for t in truths}
    s["named"] = all(s["named_each"].values())
    s["named_or_equal"] = s["named"]
    if not s["named"] and top:
        # every truth named first or beside a first finding on its joint as equally good
        word = {"coulomb": "Coulomb", "viscous": "viscous", "stribeck": "Stribeck", "gravity_load": "load"}
        beside = lambda t: any(f["joint"] == t["index"] + 1 and any(word.get(t["effect"], "?") in a
                                                                     for a in f["equally_good"]) for f in top)
        s["ambiguous"] = len(truths) == 1 and beside(truths[0])
        s["named_or_equal"] = all(any(matches(f, t) for f in top) or beside(t) for t in truths)
    for t in truths:
        f = next((f for f in findings if matches(f, t)), None)
        key = base.MAIN_PARAMETER[t["effect"]]
        if f is not None and key in f["parameters"]:
            true, fit = t["params"][key], f["parameters"][key]
            if t["effect"] == "gravity_load" and f.get("kind") == "prismatic":
                # a slide's load is G cos(angle) whatever the position: only that force is seen
                true *= math.cos(t["params"]["gravity_angle"])
                fit *= math.cos(f["parameters"]["gravity_angle"])
            s["param_ok"].append(abs(fit - true) <= 0.15 * abs(true))
            se = f["stderr"].get(key)
            if se is not None and t["effect"] != "latency":
                s["ci_ok"].append(abs(fit - true) <= CI_Z * se)
                if not s["ci_ok"][-1]:
                    s["ci_miss"].append(f"{t['effect']} true {true:.4g} fitted {fit:.4g} +- {CI_Z * se:.2g}")
        channel = t["channel"] if t["effect"] in base.FT_EFFECTS else f"{t['channel']}_{t['index'] + 1}"
        ch = next(c for c in summary["channels"] if c["name"] == channel)
        if f is not None and ch["metric"] == "rms" and ch["heldout_rms_before"] > 0:
            s["reduction"].append(1.0 - ch["heldout_rms_after"] / ch["heldout_rms_before"])
            s["ceiling"].append(ceiling.get(channel, float("nan")))
    return s


def reference_figures(table, truth_plant: PlantConfig, nominal: PlantConfig, truths: list[dict],
                      noise: dict[str, float] | None = None) -> tuple[dict[str, float], dict[str, float]]:
    """Per affected channel: the held-out RMS reduction the true plant itself reaches (the
    ceiling), and the effect's visibility: RMS of noise-free truth - noise-free nominal over
    the channel's noise. That noise is `noise` (channel_noise: an effect-free recording of the
    same motion) where the case has it, else the row-to-row scatter of the residual the tool
    sees (recording - nominal replay). The residual's own scatter holds a hunting drive's
    ripple: measured so, play or a soft gear put themselves in the denominator and read below
    2x noise however strong (0 of 12 gear cases "visible" on seed 7001, 10 of them named)."""
    from spacearm.offline.diagnosis.analysis import noise_level
    n = table.n_joints
    held = np.arange(len(table.t)) >= int(0.6 * len(table.t))
    quiet_plant = with_joints(nominal, n, 0, noise=False)
    quiet = quiet_plant == nominal.model_copy(update={"seed": 0})     # the nominal plant has no noise
    # then only the affected joints are replayed (the arms' joints are independent; noise-free, a
    # joint's columns are those of a replay of all) unless an F/T effect needs all, and the
    # nominal replay is the quiet one
    joints = None if not quiet or any(t["effect"] in base.FT_EFFECTS for t in truths) else \
        sorted({t["index"] for t in truths})
    run = lambda plant: simulate(plant, table.q_cmd, table.dt, q0=table.q[0], joints=joints)
    column = {j: c for c, j in enumerate(joints)} if joints else {j: j for j in range(n)}
    sim_true, sim_nom = run(with_joints(truth_plant, n, 0, noise=False)), run(nominal)
    quiet_nom = sim_nom if quiet else run(quiet_plant)
    ceiling, visible = {}, {}
    for t in truths:
        if t["effect"] in base.FT_EFFECTS:
            i = t["index"]
            name, pick = t["channel"], (lambda s, i=i: s.wrench[:, i])
        else:
            j, c = t["index"], column[t["index"]]
            name = f"{t['channel']}_{j + 1}"
            real_pick = (lambda s, j=j: s.q[:, j]) if t["channel"] == "q" else (lambda s, j=j: s.tau[:, j])
            sim_pick = (lambda s, c=c: s.q[:, c]) if t["channel"] == "q" else (lambda s, c=c: s.tau[:, c])
            pick = lambda s, r=real_pick, m=sim_pick: r(s) if s is table else m(s)
        real = pick(table)
        before = float(np.sqrt(np.mean((real - pick(sim_nom))[held] ** 2)))
        after = float(np.sqrt(np.mean((real - pick(sim_true))[held] ** 2)))
        ceiling[name] = 1.0 - after / before if before else float("nan")
        scatter = (noise or {}).get(name) or noise_level(real - pick(sim_nom))
        visible[name] = float(np.sqrt(np.mean((pick(sim_true) - pick(quiet_nom)) ** 2))) / scatter
    return ceiling, visible


def realtime_false_alarms(count: int, rng, nominal: PlantConfig, work: Path) -> list[bool]:
    """Effect-free recordings through the daemon on its real-time clock (jitter, skipped cycles)."""
    from spacearm.offline.diagnosis.record import record_can
    from spacearm.offline.diagnosis.recording_io import read_recording
    alarms = []
    from spacearm.offline.diagnosis.record import RecordSimError
    for k in range(count):
        kind = "ramp"
        while kind in ("two_speeds", "ramp"):
            # the daemon stops the arm above its speed limit (10 deg/s), which the drive's overshoot
            # at a triangle wave's reversal or a ramp's instant start passes: smooth motions only
            kind, traj = trajectory(rng, 6, 15.0)
        try:
            path = record_can(with_joints(nominal, 6, 900 + k), traj, work / f"realtime{k}.csv", clock="realtime")
        except RecordSimError as exc:
            print(f"realtime recording {k} not made: {exc}")
            continue
        table, _ = read_recording(path)
        result = diagnose(table, nominal)
        alarms.append(bool(result.findings or result.unexplained or result.sensor_findings))
        if alarms[-1]:
            print(f"realtime false alarm {k}: {result.verdict[:200]}")
    return alarms


def focused_cases(effect: str, count: int, seed: int, duration: float, nominal: PlantConfig, work: Path,
                  families: tuple[str, ...] | None = None, submit=None) -> list:
    """One effect alone on one joint of the 6-joint arm, scored where it is at least 2x noise
    like the main set's effects. Own generator per effect (seed + 2: Stribeck, + 3:
    elasticity, + 4: backlash). Stribeck: its level 4-30x the joint's torque noise, decay
    0.004-0.03 rad/s (the tuned families: walks, chirps, two speeds, the ramps having no
    starts from rest; --families new: those). Elasticity: 2e4 .. 3e5 N m/rad (the issue's
    5e4 in the middle); backlash 0.4 .. 5 mrad."""
    rng = np.random.default_rng(seed + {"stribeck": 2, "elasticity": 3, "backlash": 4}[effect])
    futures, submit = [], submit or (lambda fn, *args: _Done(fn(*args)))
    for k in range(count):
        kind, traj = "ramp", None
        while kind == "ramp":
            kind, traj = trajectory(rng, 6, duration, families)
        j = int(rng.integers(0, 6))
        noises = channel_noise(nominal, 6, traj, seed * 100 + 900 + k)
        noise = noises[f"tau_{j + 1}"]
        if effect == "stribeck":
            params = {"stribeck_friction": float(noise * math.exp(rng.uniform(math.log(4.0), math.log(30.0)))),
                      "stribeck_velocity": float(rng.uniform(0.004, 0.03))}
        elif effect == "elasticity":
            params = {"joint_stiffness": float(math.exp(rng.uniform(math.log(2e4), math.log(3e5))))}
        else:
            params = {"backlash": float(math.exp(rng.uniform(math.log(4e-4), math.log(5e-3))))}
        truths = [{"effect": effect, "index": j, "channel": "tau", "params": params}]
        futures.append(submit(run_focused, effect, k, kind, traj, truths, seed, nominal, work, noises))
    return futures


def run_focused(effect: str, k: int, kind: str, traj: Trajectory, truths: list[dict], seed: int,
                nominal: PlantConfig, work: Path, noise: dict[str, float]) -> dict | None:
    """One focused case (see focused_cases), scored; None if its true plant cannot be simulated."""
    started = time.perf_counter()
    j = truths[0]["index"]
    truth_plant = apply_plant(with_joints(nominal, 6, seed * 100 + 950 + k), truths)
    try:
        table = record_direct(truth_plant, traj, None, hold_cycles=0)
    except SimulationDiverged as exc:
        print(f"{effect} case {k}: the true plant itself cannot be simulated ({exc}); not scored")
        return None
    path = work / f"{effect}{k:02d}.csv"
    write_csv(path, table)
    arm_nominal = nominal_for(nominal, 6)
    ceiling, visible = reference_figures(table, truth_plant, arm_nominal, truths, noise)
    summary = write_report(diagnose(read_table(path), arm_nominal), work / f"{effect}{k:02d}", path.name,
                           arm_nominal)
    s = score(summary, {"name": path.stem, "kind": "one", "n": 6, "truths": truths, "trajectory": kind}, ceiling)
    s["visible"] = all(v >= 2.0 for v in visible.values())
    s["visibility"] = min(visible.values())
    s["trajectory"] = kind
    # named on its joint beside another law as equally good (the experiment that separates them given)
    s["beside"] = any(f["joint"] == j + 1 and (effect in f["effects"] or any(
        effect in a.lower() or (effect == "elasticity" and "stiffness" in a.lower()) for a in f["equally_good"]))
        for f in summary["findings"])
    if effect == "stribeck":
        s.update(stribeck_separation(table, truth_plant, arm_nominal, j, noise[f"tau_{j + 1}"]))
        # named beside the first as not told apart here, with the experiment that would tell them
        s["not_separated_named"] = any(f["joint"] == j + 1 and any(
            "stribeck" in a.lower() and "experiment" in a.lower() for a in f["equally_good"]) for f in summary["findings"])
    s["case_s"] = time.perf_counter() - started
    return s


def stribeck_separation(table, truth_plant: PlantConfig, nominal: PlantConfig, j: int, noise: float) -> dict:
    """Whether the recording separates the true Stribeck law from the best Coulomb + viscous
    law of joint `j` (separable.py: held-out torque RMS and breakaway peaks, each beyond its
    noise). That law: non-negative least squares of the torque residual (recording - noise-free
    nominal replay) on sign(v) and v over the training rows where the nominal joint moves."""
    from scipy.optimize import nnls
    from spacearm.offline.diagnosis.analysis import TRAIN_FRACTION, ideal_sensors
    from spacearm.offline.diagnosis.candidates import VELOCITY_DEADBAND
    from spacearm.offline.diagnosis.separable import separation
    quiet = with_joints(nominal, 6, 0, noise=False)
    replay = lambda plant: simulate(plant, table.q_cmd, table.dt, q0=table.q[0], joints=[j], wrench=False)
    v = replay(ideal_sensors(quiet)).dq[:, 0]
    y = table.tau[:, j] - replay(quiet).tau[:, 0]
    rows = (np.arange(len(v)) < int(TRAIN_FRACTION * len(v))) & (np.abs(v) > VELOCITY_DEADBAND)
    (coulomb, viscous), _ = nnls(np.c_[np.sign(v), v][rows], y[rows])
    p = quiet.joints[j]
    joints = list(quiet.joints)
    joints[j] = p.model_copy(update={"coulomb_friction": p.coulomb_friction + coulomb,
                                     "viscous_friction": p.viscous_friction + viscous})
    sep = separation(table, with_joints(truth_plant, 6, 0, noise=False), quiet.model_copy(update={"joints": joints}),
                     j, v, noise)
    return {"separable": sep.separable,
            "separation": f"true law vs Coulomb {coulomb:.3g} + viscous {viscous:.3g}: held-out RMS {100 * sep.rms_gain:.0f} "
                          f"% lower, peak error {sep.peak_gain:.2g} lower (limit {sep.peak_limit:.2g}, {sep.events} events)"}


def one_speed_case(rng, n: int, duration: float) -> tuple[Trajectory, list[dict]]:
    """One joint on a constant-speed one-way ramp, the others still; Coulomb or viscous drag."""
    t = np.arange(0.0, duration, DT)
    j = int(rng.integers(0, n))
    speed = float(rng.uniform(0.2, 0.6)) * VMAX * float(rng.choice([-1, 1]))
    q = np.repeat(home(n)[None, :], len(t), axis=0)
    q[:, j] += speed * np.clip(t - 1.0, 0.0, None)
    drag = float(rng.uniform(3.0, 10.0))
    law = str(rng.choice(["coulomb", "viscous"]))
    params = {"coulomb_friction": drag} if law == "coulomb" else {"viscous_friction": drag / abs(speed)}
    return Trajectory(t, q), [{"effect": law, "index": j, "params": params, "channel": "tau"}]


def settle(result, truth: dict, truth_plant: PlantConfig, nominal: PlantConfig, table) -> dict:
    """Whether the first diagnosis named both laws, and whether the designed experiment, run
    with the true plant (record-sim's direct path), names the true one alone."""
    from spacearm.offline.diagnosis.experiment import design_experiment, joints_to_excite, limits_from_arm
    from spacearm.offline.diagnosis.honesty import MIN_TRAVEL
    j = truth["index"]
    top = next((f for f in result.findings if f.fit.index == j and f.fit.channel == "tau"), None)
    both = top is not None and bool(top.alternatives)
    if not both:
        return {"both_named": False, "settled": False}
    joints = joints_to_excite(result, table.q, MIN_TRAVEL)
    exp = design_experiment(joints, table.q[-1], limits_from_arm(ROOT / "configs/arm/oru_testbed_6dof.toml",
                                                                 table.n_joints))
    second = diagnose(record_direct(truth_plant, exp, None), nominal)
    f = next((f for f in second.findings if f.fit.index == j and f.fit.channel == "tau"), None)
    key = base.MAIN_PARAMETER[truth["effect"]]
    ok = f is not None and f.fit.effects == (truth["effect"],) and not f.alternatives and \
        abs(f.params.get(key, np.inf) - truth["params"][key]) <= 0.15 * truth["params"][key]
    return {"both_named": True, "settled": bool(ok), "answer": f"{result.verdict[:120]} || after: {second.verdict[:160]}"}


def run_case(k: int, kind: str, n: int, traj_kind: str, traj: Trajectory, truths: list[dict],
             nominal: PlantConfig, work: Path, seed: int, noise: dict[str, float] | None = None
             ) -> tuple[dict, float, int] | None:
    """One drawn case of the main set: its recording, reference figures, diagnosis and score
    (with the case's wall time and its count of physically impossible findings). None: the
    true plant itself cannot be simulated (said, not scored)."""
    started = time.perf_counter()
    truth_plant = apply_plant(with_joints(nominal, n, seed * 100 + k), truths)
    try:
        table = record_direct(truth_plant, traj, None, hold_cycles=0)
    except SimulationDiverged as exc:
        # a true plant the simulator cannot integrate (a stiff gear on a light joint) makes no recording
        print(f"case {k} ({truths}): the true plant itself cannot be simulated ({exc}); not scored")
        return None
    before = {c: getattr(table, c).copy() for c in ("q", "dq", "tau")}
    apply_recording(table, truths)
    path = work / f"case{k:03d}.csv"
    write_csv(path, table)
    arm_nominal = nominal_for(nominal, n)
    ceiling, visible = reference_figures(table, truth_plant, arm_nominal, truths, noise)
    t1 = time.perf_counter()
    result = diagnose(read_table(path), arm_nominal)
    summary = write_report(result, work / f"case{k:03d}", path.name, arm_nominal)
    diagnosis_s = time.perf_counter() - t1
    impossible = sum(bool(parameter_violations(f["parameters"])) for f in summary["findings"])
    s = score(summary, {"name": path.stem, "kind": kind, "n": n, "truths": truths, "trajectory": traj_kind}, ceiling)
    s["visibility"] = min(visible.values()) if visible else float("nan")
    s["visible"] = all(v >= 2.0 for v in visible.values()) if kind in ("one", "two") else \
        kind != "sensor" or sensor_visibility(before[truths[0]["channel"]][:, truths[0]["index"]],
                                              getattr(table, truths[0]["channel"])[:, truths[0]["index"]]) >= 2.0
    # the commanded motion cannot separate the friction laws (or a load from them) on a joint
    # that moves one way only, nor Coulomb from viscous friction on a joint that moves at one
    # speed (both ways: c sign(v) and b v are the same drag at |v| = c / b): there, naming the
    # truth beside the first as equally good is the answer
    commanded = [np.gradient(traj.q[:, t["index"]], DT) for t in truths if t["effect"] not in base.FT_EFFECTS]
    s["one_way"] = any(one_way(v) for v in commanded)
    s["one_speed"] = any(single_speed(v) is not None for v in commanded)
    s["inseparable"] = s["one_way"] or s["one_speed"]
    s["rail"] = n == 7 and any(t["index"] == 0 and t["effect"] not in base.FT_EFFECTS for t in truths)
    if kind == "ambiguous":
        s.update(settle(result, truths[0], truth_plant, arm_nominal, table))
    s["diagnosis_s"] = diagnosis_s
    return s, time.perf_counter() - started, impossible


class _Done:
    """A result already there (a future's `result()` without a pool)."""

    def __init__(self, value):
        self.value = value

    def result(self):
        return self.value


@contextlib.contextmanager
def cases_in_parallel(jobs: int):
    """`submit(fn, *args)` -> a future: in worker processes (forked: they share this module's
    state) when jobs > 1, else at once in this one. Cases are drawn here in order, so the case
    set of a seed is the same whatever the number of workers."""
    if jobs <= 1:
        yield lambda fn, *args: _Done(fn(*args))
        return
    with ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("fork")) as pool:
        yield pool.submit


# any size will do where only which effects a case draws matters (see --effects)
_UNIT_NOISE = {f"tau_{j + 1}": 1.0 for j in range(7)} | {c: 1.0 for c in base.WRENCH_COLUMNS}


def wanted(truths: list[dict], only: set[str]) -> bool:
    """Whether a case with these truths is among the --effects asked for ('none': no truth)."""
    return any(t["effect"] in only for t in truths) or (not truths and "none" in only)


def pct(xs: list[bool]) -> str:
    """Count, share and its 95 % Wilson interval: with ten cases, 9/10 reads 60-98 %, so a
    share near a 95 % target means little without it."""
    if not xs:
        return "-"
    n, k, z = len(xs), sum(xs), 1.96
    mid, half = (k + z * z / 2) / (n + z * z), z * math.sqrt(k * (n - k) / n + z * z / 4) / (n + z * z)
    return f"{k}/{n} = {100 * k / n:.0f} % [{100 * (mid - half):.0f}-{100 * (mid + half):.0f}]"


TIMED_FAMILIES = ("chirp", "walk", "two_speeds", "ramp") + NEW_FAMILIES


def time_every_family(seed: int, nominal: PlantConfig, work: Path) -> float:
    """The issue's 60 s, 50 Hz, 7-joint recording end to end (read, replay, fit, report), once per
    trajectory family: how long the diagnosis takes depends on what the joints did (a slow ramp
    and a Fourier excitation differ by up to 10x), so one draw is no figure. Judged on the slowest.
    Process CPU beside the wall time: on a shared machine the wall follows the load."""
    rows, nominal7 = [], nominal_for(nominal, 7)
    for k, family in enumerate(TIMED_FAMILIES):
        _, traj = trajectory(np.random.default_rng(seed + 1 + k), 7, 60.0, (family,))
        table = record_direct(with_joints(nominal, 7, 5), traj, None, hold_cycles=0)
        path = work / f"timing_{family}.csv"
        write_csv(path, table)
        wall, cpu = time.perf_counter(), time.process_time()
        write_report(diagnose(read_table(path), nominal7), work / f"timing_{family}", path.name, nominal7)
        rows.append((family, time.perf_counter() - wall, time.process_time() - cpu, os.getloadavg()[0]))
    for family, wall, cpu, load in rows:
        print(f"| 60 s, 50 Hz, 7-joint recording end to end (read, replay, fit, report), {family} | "
              f"{wall:.1f} s (CPU {cpu:.1f} s, load {load:.1f}) | <= 10 s |")
    walls = [r[1] for r in rows]
    print(f"| ... every family: median / slowest ({max(rows, key=lambda r: r[1])[0]}) | "
          f"{np.median(walls):.1f} / {max(walls):.1f} s | slowest <= 10 s |")
    return float(max(walls))


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=30)
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--seed", type=int, default=7001)
    ap.add_argument("--no-timing", action="store_true")
    ap.add_argument("--jobs", type=int, default=1, help="cases run in this many worker processes (the draws stay "
                                                         "in order here: the same cases for any number)")
    ap.add_argument("--families", default="tuned", help="trajectory families: 'tuned' (chirp, walk, two speeds, "
                                                       "ramp) or 'new' (Fourier series, Panda recording, slow "
                                                       "ramps, point-to-point: never tuned on)")
    ap.add_argument("--stribeck", type=int, default=12, help="extra Stribeck-only cases sized to be seen (6 joints, "
                                                             "own draws: the main set rarely shows stiction at 2x noise)")
    ap.add_argument("--gear", type=int, default=0, help="extra elasticity-only and backlash-only cases each "
                                                         "(6 joints, own draws)")
    ap.add_argument("--realtime", type=int, default=2, help="effect-free recordings made in real time over CAN "
                                                            "(virtual bus, 15 s each)")
    ap.add_argument("--effects", default="", help="comma-separated effects (e.g. gravity_load,coulomb; 'none' for "
                                                   "the effect-free cases): run only the main set's cases that draw "
                                                   "one of them, the others drawn and skipped (the same cases as a "
                                                   "whole run of the seed); for development, not for the figures")
    args = ap.parse_args(argv)
    only = {e for e in args.effects.split(",") if e}
    rng = np.random.default_rng(args.seed)
    nominal = load_plant_config(base.NOMINAL)
    workdir = tempfile.TemporaryDirectory(prefix="concealed-")
    work = Path(workdir.name)
    kinds = ["one", "one", "sensor", "two", "none", "one", "ooc", "one", "stribeck", "none", "ambiguous"]
    scores, times, impossible, families, spent = [], [], 0, [], []
    from rich.progress import Progress
    with Progress(transient=True) as bar, cases_in_parallel(args.jobs) as submit:
        task = bar.add_task("concealed cases", total=args.cases)
        futures = []
        for k in range(args.cases):
            kind = kinds[k % len(kinds)]
            n = 7 if k % 2 else 6
            traj_kind, traj = trajectory(rng, n, args.duration, NEW_FAMILIES if args.families == "new" else None)
            families.append(traj_kind)
            noise = None     # the channels' effect-free noise, where an effect's visibility is judged
            if kind == "ambiguous":
                traj, truths = one_speed_case(rng, n, args.duration)
                traj_kind = "one-speed ramp"
            elif kind == "stribeck":
                truths = [{"effect": "stribeck", "index": int(rng.integers(0, n)), "channel": "tau",
                           "params": {"stribeck_friction": float(rng.uniform(3.0, 8.0)),
                                      "stribeck_velocity": float(rng.uniform(0.004, 0.03))}}]
                kind = "one"
                noise = channel_noise(nominal, n, traj, args.seed * 100 + k + 50)
            else:
                if only and kind in ("one", "two"):
                    # which effects this case draws, without its (slow) noise recording: the draws
                    # take the same random numbers whatever the sizes, so the case set stays the seed's
                    state = rng.bit_generator.state
                    peek = draw(rng, kind, n, traj, args.duration, _UNIT_NOISE, np.random.default_rng([args.seed, k, 31]))
                    if not wanted(peek, only):
                        continue
                    rng.bit_generator.state = state
                noise = channel_noise(nominal, n, traj, args.seed * 100 + k + 50) if kind in ("one", "two") else None
                truths = draw(rng, kind, n, traj, args.duration, noise or {}, np.random.default_rng([args.seed, k, 31]))
            if only and not wanted(truths, only):
                continue
            futures.append(submit(run_case, k, kind, n, traj_kind, traj, truths, nominal, work, args.seed, noise))
        for future in futures:
            got = future.result()
            bar.advance(task)
            if got is None:
                continue
            s, seconds, wrong = got
            scores.append(s)
            times.append(s.pop("diagnosis_s"))
            spent.append(seconds)
            impossible += wrong
    ambiguous = [s for s in scores if s["kind"] == "ambiguous"]
    one = [s for s in scores if s["kind"] == "one"]
    stribeck = [s for s in one if s["effects"] == ["stribeck"]]
    two = [s for s in scores if s["kind"] == "two"]
    hidden = [s for s in one + two if not s["visible"]]
    sensor = [s for s in scores if s["kind"] == "sensor"]
    ooc = [s for s in scores if s["kind"] == "ooc"]
    none = [s for s in scores if s["kind"] == "none"]
    params = [p for s in one + two for p in s["param_ok"]]
    cis = [c for s in one + two for c in s["ci_ok"]]
    red = [(r, c) for s in one + two for r, c in zip(s["reduction"], s["ceiling"])]
    red80 = [r for r, c in red if c >= 0.8]
    print(f"machine: {platform.node()} {platform.machine()}, python {platform.python_version()}, "
          f"load {os.getloadavg()[0]:.2f} (2 cores shared); {args.cases} cases x {args.duration:.0f} s, seed "
          f"{args.seed}, {sum(s['n'] == 7 for s in scores)} of them 7-joint")
    print("| figure | measured | target |")
    print("| --- | --- | --- |")
    single = [s for s in one if s not in stribeck and s["visible"]]
    print(f"| named and located first, single catalogue effects >= 2x noise (not Stribeck); on one-way or "
          f"one-speed motion named first or beside the first as equally good | "
          f"{pct([s['named_or_equal'] if s['inseparable'] else s['named'] for s in single])} | >= 95 % |")
    print(f"| ... the same, beside the first on one-way motion only (the rule before 2026-11-30) | "
          f"{pct([s['named_or_equal'] if s['one_way'] else s['named'] for s in single])} | - |")
    print(f"| ... the same, named first only (strict) | {pct([s['named'] for s in single])} | - |")
    seed_range = f"held-out (>= {HELD_OUT}): reported figures only, never tuned on" if args.seed >= HELD_OUT \
        else f"development (< {HELD_OUT})"
    print(f"| seed range | {seed_range} | - |")
    for effect in PLANT_EFFECTS:
        got = [s["named_each"][effect] for s in one + two if s["visible"] and effect in s.get("named_each", {})]
        if got:
            print(f"| per effect, >= 2x noise: {effect} named and located first | {pct(got)} | - |")
    small = [s["named_each"][e] for s in one + two if s["visible"] and s["visibility"] < 5.0
             for e in s.get("named_each", {}) if e in ("coulomb", "viscous", "stribeck")]
    print(f"| friction 2-5x noise (Coulomb, viscous, Stribeck) named and located first | {pct(small)} | >= 90 % |")
    print(f"| physically impossible findings (negative friction, mass, stiffness) | {impossible} | 0 |")
    print(f"| trajectory families | {args.families}: "
          f"{', '.join(sorted(set(families)))} | - |")
    print(f"| ... the same, on motion both ways at more than one speed only | "
          f"{pct([s['named'] for s in single if not s['inseparable']])} | - |")
    print(f"| Stribeck named and located first, >= 2x noise | {pct([s['named'] for s in stribeck if s['visible']])} "
          "| >= 80 % |")
    print(f"| Stribeck named and located first, all drawn (3-8 N m, brief at starts) | "
          f"{pct([s['named'] for s in stribeck])} | - |")
    print(f"| two effects both named first (one-way or one-speed motion: or beside as equally good), >= 2x noise | "
          f"{pct([s['named_or_equal'] if s['inseparable'] else s['named'] for s in two if s['visible']])} | >= 85 % |")
    print(f"| ... the same, beside the first on one-way motion only (the rule before 2026-11-30) | "
          f"{pct([s['named_or_equal'] if s['one_way'] else s['named'] for s in two if s['visible']])} | - |")
    print(f"| effects below 2x noise (not scored above), named anyway | {pct([s['named'] for s in hidden])} | - |")
    print(f"| single effects not named first but named as equally good beside it (one speed / one way) | "
          f"{sum(s['ambiguous'] for s in one)} of {len(one)} | - |")
    print(f"| one-speed one-way ramps: both laws named as equally good | "
          f"{pct([s['both_named'] for s in ambiguous])} | - |")
    print(f"| ... then settled by the designed experiment (true law first, no alternative, within 15 %) | "
          f"{pct([s['settled'] for s in ambiguous])} | - |")
    print(f"| sensor effects named (velocity lag, quantisation), >= 2x the channel's white noise | "
          f"{pct([s['named'] for s in sensor if s['visible']])} | - |")
    print(f"| sensor effects named, all drawn (a velocity lag on a constant speed changes nothing) | "
          f"{pct([s['named'] for s in sensor])} | - |")
    print(f"| out-of-catalogue flagged unexplained on its channel | {pct([s['named'] for s in ooc])} | >= 80 % |")
    print(f"| false alarms on effect-free recordings (direct path) | {pct([s['alarm'] for s in none])} | <= 2 % |")
    print(f"| fitted main parameter within 15 % | {pct(params)} | >= 90 % |")
    print(f"| stated 95 % interval covers the truth | {pct(cis)} | >= 90 % |")
    if red:
        ceil = [c for _, c in red if np.isfinite(c)]
        print("| held-out RMS reduction, median, where the true plant reaches >= 80 % | "
              + (f"{100 * np.median(red80):.0f} % ({len(red80)} channels)" if red80 else "-")
              + " | >= 80 % |")
        print(f"| held-out RMS reduction, median, all named | {100 * np.median([r for r, _ in red]):.0f} % "
              f"(true-plant ceiling median {100 * np.median(ceil):.0f} %) | - |")
    rail = [s for s in scores if s["rail"] and s["kind"] in ("one", "two", "sensor", "ooc")]
    print(f"| effects on the prismatic rail (joint 1 of the 7-joint arm) named / flagged on it | "
          f"{pct([s['named'] for s in rail])} | - |")
    print(f"| ... their fitted main parameter within 15 % / interval covers | "
          f"{pct([p for s in rail for p in s['param_ok']])} / {pct([c for s in rail for c in s['ci_ok']])} | - |")
    if times:
        print(f"| diagnosis time per {args.duration:.0f} s recording, median | {np.median(times):.1f} s | - |")
        print(f"| whole case (recording, reference replays, diagnosis, score), median / mean / max, {args.jobs} "
              f"worker(s) | {np.median(spent):.1f} / {np.mean(spent):.1f} / {np.max(spent):.1f} s | - |")
    answered = lambda s: s["named_or_equal"] if s.get("inseparable") and "named_or_equal" in s else s["named"]
    misses = [s for s in scores if (s["kind"] not in ("none", "ambiguous") and not answered(s) and s["visible"])
              or (s["kind"] == "ambiguous" and not s["settled"])
              or (s["kind"] == "none" and s["alarm"])]
    for s in scores:
        for m in s["ci_miss"]:
            print(f"interval miss {s['name']} [{s['n']} joints]: {m}")
    for s in misses:
        print(f"miss {s['name']} [{s['kind']}, {s['n']} joints] {s['truth']}: {s['answer']}")
    for s in scores:
        if s["rail"]:
            print(f"rail {s['name']} [{s['kind']}] {s['truth']}: named {s['named']}, within 15 % {s['param_ok']}, "
                  f"interval covers {s['ci_ok']}, reduction {[round(r, 2) for r in s['reduction']]}, units {s['units']}: "
                  f"{s['answer'][:200]}")
    out = {"scores": scores}
    fams = NEW_FAMILIES if args.families == "new" else None
    with cases_in_parallel(args.jobs) as submit:
        pending = [(effect, focused_cases(effect, count, args.seed, args.duration, nominal, work, fams, submit))
                   for effect, count in (("stribeck", args.stribeck), ("elasticity", args.gear),
                                         ("backlash", args.gear)) if count]
        for effect, futures in pending:
            drawn = [s for s in (f.result() for f in futures) if s is not None]
            if drawn:
                print(f"| {effect}-only whole case time, median / max | {np.median([s['case_s'] for s in drawn]):.1f} / "
                      f"{np.max([s['case_s'] for s in drawn]):.1f} s | - |")
            seen = [s for s in drawn if s["visible"]]
            print(f"| {effect}-only cases >= 2x noise ({len(seen)} of {len(drawn)}): named and located first | "
                  f"{pct([s['named'] for s in seen])} | >= 80 % |")
            print(f"| ... named first or beside the first as equally good (with the separating experiment) | "
                  f"{pct([s['beside'] for s in seen])} | - |")
            print(f"| ... all drawn: named first | {pct([s['named'] for s in drawn])} | - |")
            if effect == "stribeck":
                # the old judging above, the new beside it: the criterion decides per case, from the truth
                fair = [s["named"] or (not s["separable"] and s["not_separated_named"]) for s in seen]
                print(f"| {effect}-only >= 2x noise, new judging: named first, or, where the recording cannot separate "
                      f"the true law from the best Coulomb + viscous law (held-out torque RMS < 5 % lower and held-out "
                      f"breakaway peak error not lower by 2 standard errors: separable.py), named beside the first as "
                      f"not separable with the separating experiment | {pct(fair)} | >= 80 % |")
                print(f"| ... cases the recording cannot separate by that criterion (their old judging / new) | "
                      f"{sum(not s['separable'] for s in seen)} of {len(seen)} "
                      f"({sum(s['named'] for s in seen if not s['separable'])} / "
                      f"{sum(f for f, s in zip(fair, seen) if not s['separable'])} answered) | - |")
            print(f"| ... main parameter within 15 % / stated interval covers (all named) | "
                  f"{pct([p for s in drawn for p in s['param_ok']])} / {pct([c for s in drawn for c in s['ci_ok']])} | - |")
            out[effect] = drawn
            for s in drawn:
                for m in s["ci_miss"]:
                    print(f"interval miss {s['name']}: {m}")
                if not s["named"]:
                    print(f"miss {s['name']} [{s['trajectory']}] (visibility {s['visibility']:.1f}) {s['truth']}: "
                          f"{s['answer']}" + (f" [{'separable' if s['separable'] else 'NOT separable'}: "
                                              f"{s['separation']}]" if "separable" in s else ""))
    if args.realtime:
        alarms = realtime_false_alarms(args.realtime, rng, nominal, work)
        print(f"| false alarms on effect-free recordings made in real time (CAN, daemon realtime clock) | "
              f"{pct(alarms)} | <= 2 % |")
    if not args.no_timing:
        out["timing_s"] = time_every_family(args.seed, nominal, work)
    return out


if __name__ == "__main__":
    main()
