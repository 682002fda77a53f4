"""The diagnosis pipeline: replay, residuals, locate, name, fit, re-simulate, compare.

    result = diagnose(table, nominal_plant_config)

1. Replay the recording's commands through the nominal plant (direct path) or take a
   given simulation; row k of both answers the command of row k-1.
2. Residual per channel; noise from the row-to-row differences (robust, MAD).
3. Torque and F/T channels first: fit every candidate (and pairs) on the first 60 % of the
   rows (torque: the rows where the joint moves), keep the one with the lowest BIC, at one
   block length common to the channel's candidates, among those that pass the significance
   test, reduce the held-out (last 40 %) error and simulate; refine its size by single-joint
   replays (sim_refit); rank findings by explained variance over noise.
4. Write the chosen effects into a copy of the plant, re-simulate, and look at the position
   channels again (feedback latency), so tracking errors that friction explains are not
   named twice.
5. RMS before/after on the held-out rows from the re-simulation with the fitted plant; the
   mismatch statistic of each channel against noise and against a second nominal replay
   started half a resolver quantum away (the null: what differs without missing physics).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from spacearm.offline.diagnosis.candidates import (FT_CANDIDATES, TORQUE_PAIRS, VELOCITY_DEADBAND, Signals, by_name,
                                                   joint_candidates)
from spacearm.offline.diagnosis.direct_sim import SimTraces, drive_settings, rated_joint_torque, simulate
from spacearm.offline.diagnosis.fitting import ChannelFit, common_block, fit_candidate, fit_pair
from spacearm.offline.diagnosis.fit_parameters import apply_fits, describe, plant_parameters, stroke_load_text
from spacearm.offline.diagnosis.gear_effects import GEAR_EFFECTS, envelope, fit_gear_effect
from spacearm.offline.diagnosis.stiff_gear import chatters_more, fit_chattering_gear, fit_stiff_gear
from spacearm.offline.diagnosis.stiff_gear import significant as stiff_significant
from spacearm.offline.diagnosis.honesty import (confirmed, count_reversals, equally_good, load_at_centre,
                                                load_unknown, moved, stiction_unseparated, uncertain)
from spacearm.offline.diagnosis.joint_units import units_of
from spacearm.offline.diagnosis.physical import parameter_violations
from spacearm.offline.diagnosis.sensor_effects import SensorFinding, sensor_findings
from spacearm.offline.diagnosis.recording_io import RecordingTable
from spacearm.offline.diagnosis.breakaway import at_breakaway
from spacearm.offline.diagnosis.chatter_spectrum import fit_spectral_gear, screened
from spacearm.offline.diagnosis.sim_refit import refine_size, refine_stiction
from spacearm.offline.diagnosis.stick_slip import stiction_by_breakaway
from spacearm.offline.diagnosis.stick_slip_envelope import stiction_by_swing
from spacearm.offline.diagnosis.stribeck_replay import stribeck_by_replay
from spacearm.controller.recording.csv_export import WRENCH_COLUMNS
from spacearm.firmware_sim.plant import PlantConfig

TRAIN_FRACTION = 0.6


@dataclass
class Finding:
    fit: ChannelFit
    score: float                 # explained variance (held-out) over noise variance
    params: dict[str, float]     # plant parameters (SI)
    stderr: dict[str, float]
    text: str
    onset: float | None = None   # first change point of the channel's residual, s
    alternatives: list[str] = field(default_factory=list)   # laws that explain the data as well


@dataclass
class ChannelResult:
    name: str
    noise: float
    rms_before: float            # held-out, nominal sim
    rms_after: float             # held-out, fitted sim
    significant: bool = False    # a named effect acts on it
    excess_before: float = 0.0   # whole-recording mismatch statistic vs nominal (see mismatch_statistic)
    excess_after: float = 0.0    # the same vs the fitted simulation
    metric: str = "rms"          # "envelope": hunting/ringing, compared by its 0.5 s RMS envelope
    onset: float | None = None   # where the fitted simulation's residual first changes, s (unexplained only)

    @property
    def unexplained(self) -> bool:
        return self.excess_after > 1.0


@dataclass
class Diagnosis:
    findings: list[Finding]
    channels: list[ChannelResult]
    updated: PlantConfig
    heldout_start: float
    timings: dict[str, float] = field(default_factory=dict)
    residual_before: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    residual_after: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    t: np.ndarray | None = field(default=None, repr=False)
    not_reported: list[str] = field(default_factory=list)   # fits left out, and why
    sensor_findings: list[SensorFinding] = field(default_factory=list)
    repairs: list[str] = field(default_factory=list)          # how the time base was repaired (rows dropped, ...)

    @property
    def model_wrong(self) -> list[str]:
        """Fits that needed a physically impossible value: where the model is wrong, not a finding."""
        return [w for w in self.not_reported if w.startswith(MODEL_WRONG)]

    @property
    def unexplained(self) -> list[ChannelResult]:
        return [c for c in self.channels if c.unexplained]

    @property
    def verdict(self) -> str:
        if not self.findings and not self.unexplained and not self.sensor_findings and not self.model_wrong:
            return "no significant mismatch between the recording and the nominal simulation"
        words = [s.text for s in self.sensor_findings] + [f.text + "".join(f" -- or equally well: {a}" for a in f.alternatives) for f in self.findings]
        words += [w.replace(" (not reported)", "") for w in self.model_wrong]
        if self.unexplained:
            words.append("mismatch no catalogue effect explains on " + ", ".join(
                f"{c.name} ({c.excess_after:.1f}x the significance threshold"
                + (f", from t = {c.onset:.1f} s" if c.onset is not None else "") + ")" for c in self.unexplained))
        return "; ".join(words)


def noise_level(residual: np.ndarray) -> float:
    """Row-to-row scatter of a residual (std of differences / sqrt 2). Not a robust (MAD)
    estimate on purpose: resolver chatter makes sparse torque spikes of Kp x one quantum
    that belong to the noise, not to a physical effect."""
    return float(np.std(np.diff(residual)) / math.sqrt(2.0)) + 1e-12


RAW_RATIO_LIMIT = 1.5      # residual RMS / noise: 1.0-1.3 without any effect (measured, random starts)
SMOOTH_RATIO_LIMIT = 0.6   # 0.5 s moving-average RMS / noise: 0.2-0.45 without any effect


NULL_MARGIN = 2.0          # one draw of the null replay's average, scattered up to about 1.7x (measured)
STIFF_GEAR_BETTER = 1.0     # a stiff gear replaces a law fitted first that explains the torque no better
HUNTING_RATIO = 5.0        # residual RMS / median noise of the torque channels: a drive that hunts


def smoothed_rms(residual: np.ndarray, window: int = 25) -> float:
    """RMS of the residual's moving average over `window` rows (0.5 s at 50 Hz)."""
    return float(np.sqrt(np.mean(np.convolve(residual, np.ones(window) / window, mode="valid") ** 2)))


def mismatch_statistic(residual: np.ndarray, noise_floor: float, window: int = 25,
                       reference_noise: float | None = None, null_smooth: float = 0.0,
                       parked: np.ndarray | None = None, parked_dither: float = 0.0) -> float:
    """How far a residual is from noise, as a multiple of the limit (> 1: significant).

    Two views: the raw RMS against the row-to-row noise (catches ringing and hunting) and the
    0.5 s average (catches slow offsets hidden in noise). The limits hold for the servo's
    resolver chatter, which is not white; measured on effect-free recordings. `null_smooth`
    is the 0.5 s average RMS between two equally valid nominal replays (see null_replay):
    where the arm rests, the servo parks anywhere within a resolver quantum, and that
    offset, not the chatter, sets what the average shows without any effect.

    `parked` (rows where the joint holds its commanded position) and `parked_dither` (the RMS
    by which two equally valid replays differ there): a joint parked between two resolver
    readings dithers between them faster than the rows sample it, with a phase set by its
    sub-quantum state, which no recording gives (a real servo dithers between encoder counts
    alike). Even the true plant replays that dither out of phase, so in those rows the "drive
    hunts" view compares with the dither, not with the quieter joints' noise alone."""
    noise = max(noise_level(residual), noise_floor)
    raw = float(np.sqrt(np.mean(residual ** 2))) / noise
    smooth = smoothed_rms(residual, window)
    stat = max(raw / RAW_RATIO_LIMIT, smooth / max(SMOOTH_RATIO_LIMIT * noise, NULL_MARGIN * null_smooth))
    if reference_noise:
        # dense ringing (a hunting drive) inflates the channel's own row-to-row noise estimate:
        # compare with the noise the other channels of the same kind show
        parked = np.zeros(len(residual), bool) if parked is None else parked
        for rows, reference in ((~parked, reference_noise), (parked, max(reference_noise, parked_dither))):
            if rows.sum() >= min(window, len(residual)):     # a few rows alone (a joint's first nudge) say nothing
                stat = max(stat, float(np.sqrt(np.mean(residual[rows] ** 2))) / reference / HUNTING_RATIO)
    return stat


def replay(table: RecordingTable, plant: PlantConfig, joints: list[int] | None = None,
           wrench: bool | None = None) -> SimTraces:
    """`wrench` (default: a replay of every joint reads the F/T channel) see direct_sim.simulate."""
    return simulate(plant, table.q_cmd, table.dt, q0=table.q[0], dq_cmd=table.dq_cmd, joints=joints, t0=0.0,
                    wrench=joints is None if wrench is None else wrench)


def null_replay(table: RecordingTable, plant: PlantConfig) -> SimTraces:
    """The nominal replay from half a resolver quantum away: the recording's first position
    is only known to a quantum, so this replay is as valid as the other, and how much the
    two differ is what the recording may differ from either without any missing physics."""
    n = table.q.shape[1]
    quantum = np.array([plant.joint_params(j).position_quantum for j in range(n)])
    return simulate(plant, table.q_cmd, table.dt, q0=table.q[0] + 0.5 * quantum, dq_cmd=table.dq_cmd, t0=0.0)


def _signals(table: RecordingTable, sim: SimTraces, j: int) -> Signals:
    t = table.t - table.t[0]
    return Signals(t, sim.q[:, j], sim.dq[:, j], sim.tau[:, j], table.dt)


STUCK_SPEED = 1e-3           # rad/s: a recorded joint slower than this sticks (resolver steps are ~6e-3 rad/s per cycle)


def stuck(dq_recorded: np.ndarray) -> np.ndarray:
    """Rows where the recorded joint rests (all False if the recording has no velocity)."""
    if not np.any(dq_recorded):
        return np.zeros(len(dq_recorded), bool)
    return np.abs(dq_recorded) < STUCK_SPEED


def _envelope_error(fit: ChannelFit, residual: np.ndarray, noise: float, rows: np.ndarray) -> float:
    """A fit's error on the residual's RMS envelope (how gear effects are judged), for comparison."""
    if fit.by_envelope:
        return fit.rms_heldout_after
    predicted = np.sqrt(envelope(fit.prediction) ** 2 + noise ** 2)
    return float(np.sqrt(np.mean((envelope(residual)[rows] - predicted[rows]) ** 2)))


def _ranked(fits: list[ChannelFit]) -> list[ChannelFit]:
    """The significant fits, best (lowest BIC at one common block length) first."""
    good = [f for f in fits if f.significant]
    block = common_block(good) if good else 1
    return sorted(good, key=lambda f: f.bic_at(block))


def _best_for_channel(fits: list[ChannelFit]) -> ChannelFit | None:
    ranked = _ranked(fits)
    return ranked[0] if ranked else None


def _torque_fits(table: RecordingTable, sim: SimTraces, quiet: SimTraces, j: int,
                 train: np.ndarray, kind: str = "revolute") -> list[ChannelFit]:
    """Significant torque-channel explanations of joint j (of this kind), best first."""
    s = _signals(table, quiet, j)
    y = table.tau[:, j] - sim.tau[:, j]
    # Rows where the nominal joint rests are left out of the fits: with static friction the
    # real joint sticks wherever break-away left it, a torque offset no smooth model predicts
    # and that, kept in, only dilutes the rows where friction shows (and the noise estimate).
    fit_rows = train & (np.abs(s.dq) > VELOCITY_DEADBAND)
    # ... and so are rows where the recorded joint sticks while the nominal one moves: static
    # friction there holds any torque up to break-away, not the kinetic law, and kept in they
    # pulled a stiction level about 15 % low (measured on the concealed bench)
    fit_rows &= ~stuck(table.dq[:, j])
    if fit_rows.sum() < 0.2 * train.sum():
        fit_rows = train
    # judged on the same kind of rows: at rest a sticking joint holds whatever torque it
    # stopped with, which no candidate predicts and which would hide a stiction bump
    held = ~train & (np.abs(s.dq) > VELOCITY_DEADBAND)
    if held.sum() < 0.2 * (~train).sum():
        held = ~train
    fits = {c.effect: fit_candidate(c, s, y, fit_rows, j, held) for c in joint_candidates(kind) if c.channel == "tau"}
    ranked = _ranked(list(fits.values()))
    if not ranked:
        return []
    best = ranked[0]
    pairs = []
    for a, b in TORQUE_PAIRS:
        if best.effects[0] in (a, b):
            pairs.append(fit_pair(by_name(a, kind), by_name(b, kind), s, y, fit_rows, j, fits[a].shape[0],
                                  fits[b].shape[0], held))
    pair = _best_for_channel(pairs)
    block = common_block([best, pair]) if pair is not None else 1
    # a second effect must earn its place: lower BIC and clearly lower held-out error
    if pair is not None and pair.bic_at(block) < best.bic_at(block) and \
            pair.rms_heldout_after < 0.9 * best.rms_heldout_after:
        return [pair] + ranked
    return ranked


def _simulates(table: RecordingTable, nominal: PlantConfig, fit: ChannelFit) -> bool:
    """Whether the plant with this fit alone replays without diverging. A friction so stiff
    that the simulator cannot integrate it is no usable model (and, on a one-way ramp, a
    constant torque is explained as well by Coulomb or Stribeck friction, which simulate)."""
    try:
        with np.errstate(all="raise"):
            sim = replay(table, apply_fits(nominal, [fit]), joints=[fit.index])
        return bool(np.all(np.isfinite(sim.q)) and np.all(np.isfinite(sim.tau)))
    except (OverflowError, FloatingPointError, ValueError):
        return False


def _ft_fit(table: RecordingTable, sim: SimTraces, axis: int, train: np.ndarray) -> ChannelFit | None:
    t = table.t - table.t[0]
    s = Signals(t, t, t, t, table.dt)
    y = table.wrench[:, axis] - sim.wrench[:, axis]
    return _best_for_channel([fit_candidate(c, s, y, train, axis) for c in FT_CANDIDATES])


def _latency_fit(table: RecordingTable, sim: SimTraces, j: int, train: np.ndarray) -> ChannelFit | None:
    s = _signals(table, sim, j)
    y = table.q[:, j] - sim.q[:, j]
    return _best_for_channel([fit_candidate(by_name("latency"), s, y, train, j)])


def _onset(t: np.ndarray, residual: np.ndarray, noise: float) -> float | None:
    """First change point of the smoothed residual (ruptures, PELT), if any."""
    import ruptures
    step = max(1, len(residual) // 600)
    x = np.convolve(residual, np.ones(step) / step, mode="valid")[::step]
    if len(x) < 10:
        return None
    scale = max(noise / math.sqrt(step), 1e-12)
    points = ruptures.Pelt(model="l2", min_size=5).fit(x / scale).predict(pen=20 * math.log(len(x)))
    points = [p for p in points if p < len(x)]
    return float(t[min(points[0] * step, len(t) - 1)]) if points else None


def diagnose(table: RecordingTable, nominal: PlantConfig, sim: SimTraces | None = None,
             progress: Callable[[str, float], None] | None = None) -> Diagnosis:
    """`progress(stage, fraction done)` is called between stages (the console's progress bar)."""
    timings = {}
    started = time.perf_counter()
    report = progress or (lambda stage, done: None)
    n_rows, n = table.q.shape
    report("nominal replay", 0.0)
    replayed = sim is None
    if replayed:
        sim = replay(table, nominal)
    timings["replay_s"] = time.perf_counter() - started
    train = np.zeros(n_rows, bool)
    train[: int(TRAIN_FRACTION * n_rows)] = True
    t = table.t - table.t[0]

    fits: list[ChannelFit] = []
    # Candidate features come from a replay with ideal resolvers: a feature built from the
    # nominal replay's own quantisation chatter would "explain" the chatter in the residual.
    # (its joints only: the features never read its F/T channel, a fifth of a full replay's cost)
    quiet = replay(table, ideal_sensors(nominal), wrench=False)
    tau_noise = float(np.median([noise_level(table.tau[:, j] - sim.tau[:, j]) for j in range(n)]))
    null = null_replay(table, nominal)
    # what each joint's torque differs by between two equally valid nominal replays: a fast
    # light joint chatters far above the median noise without any effect, which is no hunting
    chatter = [float(np.sqrt(np.mean((null.tau[:, j] - sim.tau[:, j]) ** 2))) for j in range(n)]
    # a joint that did not move excited nothing: no finding there (its fits are noise)
    active = [j for j in range(n) if moved(table.q[:, j], quiet.dq[:, j])]
    alternatives: dict[int, list[ChannelFit]] = {}
    settings = drive_settings(nominal, n)
    quanta = ([nominal.joint_params(j).position_quantum for j in range(n)],   # torque: 6077h is per mille
              [rated_joint_torque(settings[j], nominal.joint_params(j)) / 1000.0 for j in range(n)])
    kinds = [nominal.joint_params(j).kind for j in range(n)]
    sensors = sensor_findings(table.q, table.dq, table.tau, table.dt, (sim.q, sim.dq), quanta, active, kinds,
                              table.q_cmd)
    coarse_torque = {f.joint for f in sensors if f.effect == "torque_quantisation"}
    for j in active:
        report(f"fitting joint {j + 1}", 0.1 + 0.6 * j / n)
        ranked = _torque_fits(table, sim, quiet, j, train, kinds[j])
        if j in coarse_torque:
            # a coarse torque quantum clips small torques to zero: that is no drive saturation
            ranked = [f for f in ranked if f.effects != ("torque_saturation",)]
        # stiction whose size this recording cannot pin down (a one-way ramp) is neither chosen
        # nor named beside the choice: chosen, it was dropped as unknown later and the joint left
        # "unexplained" (a load's linear standard error is no guide here: its cos and sin parts
        # trade off over a short stroke, while the refined amplitude is well known)
        ranked = [f for f in ranked if "stribeck" not in f.effects or not uncertain(*plant_parameters(f))]
        fit = next((f for f in ranked if _simulates(table, nominal, f)), None)
        if fit is not None:
            alternatives[j] = equally_good(fit, ranked, quiet.dq[:, j])
            fit = refine_size(fit, nominal, table.q_cmd, table.dt, table.q[0], table.tau[:, j],
                              train & (np.abs(quiet.dq[:, j]) > VELOCITY_DEADBAND), apply_fits, table.dq_cmd)
            fit = refine_stiction(fit, nominal, table.q_cmd, table.dt, table.q[0], table.tau[:, j], train, apply_fits,
                                  table.dq_cmd)
            fit, alternatives[j] = replayed_choice(fit, alternatives[j], table, nominal, j, train, quiet.dq[:, j])
            running = (np.abs(quiet.dq[:, j]) > VELOCITY_DEADBAND) & ~stuck(table.dq[:, j])
            fit = at_breakaway(fit, table.tau[:, j] - quiet.tau[:, j], quiet.dq[:, j], train, table.dt, tau_noise,
                               running)
        if fit is None or set(fit.effects) <= {"coulomb", "viscous", "stribeck"}:
            # a running law (or none) may miss stiction that shows only where the joint breaks free;
            # and a Stribeck law sized row by row sits low where the joint sticks and slips (a slip
            # replayed out of phase costs more the larger it is: 80 N m of stiction between
            # point-to-point moves was stated 25 N m): its breakaway peaks size it there
            sticking = stiction_by_breakaway(fit, j, nominal, apply_fits, table.q_cmd, table.dt, table.q[0],
                                             table.dq_cmd, table.tau[:, j], sim.tau[:, j], quiet.dq[:, j],
                                             np.abs(quiet.dq[:, j]) > VELOCITY_DEADBAND, train,
                                             tau_noise, table.dq[:, j],
                                             tuple(a for a in alternatives.get(j, [])
                                                   if set(a.effects) <= {"coulomb", "viscous"}))
            if sticking is not None:
                fit, alternatives[j] = sticking, []
            elif fit is not None and fit.judged_by == "samples":
                # on slow motion that reverses, stiction shows in how each reversal swings, which a
                # running law, or a Stribeck law sized row by row, misses (stribeck_replay.py)
                swing = stribeck_by_replay(fit, j, nominal, apply_fits, table.q_cmd, table.dt, table.q[0],
                                           table.dq_cmd, table.tau[:, j], quiet.dq[:, j],
                                           np.abs(quiet.dq[:, j]) > VELOCITY_DEADBAND, train)
                if swing is None:
                    # slower still, stiction that falls to the running level drives stick-slip along
                    # the whole run, judged by its envelope (stick_slip_envelope.py)
                    swing = stiction_by_swing(fit, j, nominal, apply_fits, table.q_cmd, table.dt, table.q[0],
                                              table.dq_cmd, table.tau[:, j], quiet.dq[:, j],
                                              np.abs(quiet.dq[:, j]) > VELOCITY_DEADBAND, train)
                if swing is not None:
                    fit, alternatives[j] = swing, []
        residual = table.tau[:, j] - sim.tau[:, j]
        left = residual if fit is None else residual - fit.prediction
        own_noise = max(tau_noise, chatter[j])
        if mismatch_statistic(left, 1e-3, reference_noise=tau_noise) > 1.0 and \
                float(np.sqrt(np.mean(left ** 2))) > HUNTING_RATIO * own_noise:
            # the drive hunts or rings: try the gear effects (simulated, compared by envelope)
            gears = []
            for effect in GEAR_EFFECTS:
                gear = fit_gear_effect(effect, nominal, table.q_cmd, table.dt, table.q[0], quiet.tau[:, j], residual,
                                       tau_noise, j, train, base_q=quiet.q[:, j], q_residual=table.q[:, j] - quiet.q[:, j],
                                       dq_cmd=table.dq_cmd)
                if gear.significant:
                    gears.append(gear)
                if gear.significant and (fit is None or gear.rms_heldout_after < 0.7 * _envelope_error(
                        fit, residual, tau_noise, ~train)):
                    fit = gear
        else:
            gears = []
        if kinds[j] == "revolute" and (fit is None or not fit.by_envelope) and \
                mismatch_statistic(residual, 1e-3, reference_noise=tau_noise) > 1.0:
            # no ringing: a stiff gear's smooth, phase-locked torque term (a load law fitted to it
            # explains the torque as well but moves the link, and is dropped later); the search
            # range is a rotary gear's (N m/rad), so a linear rail is left out
            stiff = fit_stiff_gear(nominal, table.q_cmd, table.dt, table.q[0], quiet.tau[:, j], residual, j, train,
                                   table.dq_cmd)
            if _stiff_gear_wins(stiff, fit):
                fit, alternatives[j] = stiff, []
        if kinds[j] == "revolute" and (fit is None or not fit.by_envelope) and \
                (fit is None or fit.effects != ("elasticity",)) and chatters_more(residual, chatter[j]):
            # stiffer still, the gear shows in the drive's chatter, which only a replay with the
            # nominal's resolver reproduces (stiff_gear.py)
            stiff = fit_chattering_gear(nominal, table.q_cmd, table.dt, table.q[0], sim.tau[:, j], residual, j, train,
                                        table.dq_cmd)
            if _stiff_gear_wins(stiff, fit):
                fit, alternatives[j] = stiff, []
        chosen = sim.tau[:, j] + (0.0 if fit is None else fit.prediction)
        if kinds[j] == "revolute" and (fit is None or fit.judged_by == "breakaway") and \
                screened(*(x - quiet.tau[:, j] for x in (table.tau[:, j], chosen, sim.tau[:, j], null.tau[:, j])),
                         train):
            # a gear that shows only in how the drive chatters, out of phase with every replay: judged
            # by the chatter's spectrum (chatter_spectrum.py), and against stiction read from the
            # same reversals by that stiction's own replay
            gear = fit_spectral_gear(nominal, table.q_cmd, table.dt, table.q[0], quiet.tau[:, j], sim.tau[:, j],
                                     table.tau[:, j], null.tau[:, j], j, train, table.dq_cmd,
                                     () if fit is None else (chosen,))
            if gear is not None and gear.significant:
                fit, alternatives[j] = gear, []
        if fit is not None:
            if fit.by_envelope:
                # play and a soft gear both make the drive hunt; where their envelopes fit alike
                # the recording cannot tell them apart: both are named, with the experiment that can
                alternatives[j] = gear_alternatives(fit, gears)
            fits.append(fit)
    for axis in range(6):
        fit = _ft_fit(table, sim, axis, train)
        if fit is not None:
            fits.append(fit)
    timings["fit_s"] = time.perf_counter() - started - timings["replay_s"]

    report("re-simulating with the fits", 0.7)
    updated, refit = _stable_refit(table, nominal, fits, sim, replayed)
    for j in active:
        fit = _latency_fit(table, refit, j, train)
        if fit is not None:
            fits.append(fit)
    if any(f.effects == ("latency",) for f in fits):
        updated, refit = _stable_refit(table, nominal, fits, sim, replayed)
    timings["refit_s"] = time.perf_counter() - started - timings["replay_s"] - timings["fit_s"]

    not_reported: list[str] = []
    report("held-out comparison", 0.85)
    while True:
        channels, before, after = _channel_results(table, nominal, sim, refit, train, tau_noise, null)
        findings, rejected = _findings(fits, channels, before, quiet, t, alternatives, kinds)
        if not rejected:
            break
        # an effect the held-out re-simulation does not confirm, or whose size is not known,
        # is no improvement to report: drop it and judge the others without it
        for fit, why in rejected:
            fits.remove(fit)
            not_reported.append(why)
        updated, refit = _stable_refit(table, nominal, fits, sim, replayed)
    for c in channels:
        if c.unexplained:
            c.onset = _onset(t, after[c.name], c.noise)
    findings.sort(key=lambda f: -f.score)
    timings["judge_s"] = time.perf_counter() - started - timings["replay_s"] - timings["fit_s"] - timings["refit_s"]
    timings["total_s"] = time.perf_counter() - started
    report("done", 1.0)
    return Diagnosis(findings, channels, updated, float(t[int(TRAIN_FRACTION * n_rows)]), timings, before, after, t,
                     not_reported, sensors)


def _channel_results(table: RecordingTable, nominal: PlantConfig, sim: SimTraces, refit: SimTraces,
                     train: np.ndarray, tau_noise: float, null_sim: SimTraces | None = None):
    """Per channel: noise, held-out RMS against the nominal and the fitted simulation, and the
    mismatch statistics (see mismatch_statistic)."""
    n = table.q.shape[1]
    held = ~train
    channels, before, after = [], {}, {}
    quantum = [nominal.joint_params(j).position_quantum for j in range(n)]
    null_sim = null_sim if null_sim is not None else null_replay(table, nominal)
    null = dict((name, real - nom) for name, real, nom, _ in _channels(null_sim, sim, sim))
    for name, real, nom, fitted in _channels(table, sim, refit):
        r0, r1 = real - nom, real - fitted
        null_smooth = smoothed_rms(null[name])
        hunting = {}
        if name.startswith("tau"):
            still = np.diff(table.q_cmd[:, int(name[4:]) - 1]) == 0.0
            parked = np.r_[still[:1], still]
            dither = float(np.sqrt(np.mean(null[name][parked] ** 2))) if parked.any() else 0.0
            hunting = {"reference_noise": tau_noise, "parked": parked, "parked_dither": dither}
        before[name], after[name] = r0, r1
        floor = (quantum[int(name[2:]) - 1] if name.startswith("q_") else 0.01 if name.startswith("f") else 0.001) \
            / math.sqrt(12.0) if not name.startswith("tau") else 1e-3
        channels.append(ChannelResult(name, max(noise_level(r0), floor), float(np.sqrt(np.mean(r0[held] ** 2))),
                                      float(np.sqrt(np.mean(r1[held] ** 2))), False,
                                      mismatch_statistic(r0, floor, null_smooth=null_smooth, **hunting),
                                      mismatch_statistic(r1, floor, null_smooth=null_smooth, **hunting)))
    return channels, before, after


def _findings(fits: list[ChannelFit], channels: list[ChannelResult], before: dict[str, np.ndarray],
              quiet: SimTraces, t: np.ndarray, alternatives: dict[int, list[ChannelFit]], kinds: list[str]):
    """Findings in words, and the fits that may not be reported (with the reason)."""
    findings, rejected = [], []
    for fit in fits:
        name = _channel_name(fit)
        ch = next(c for c in channels if c.name == name)
        params, errs = plant_parameters(fit)
        reversals = count_reversals(quiet.dq[:, fit.index]) if fit.channel == "tau" else None
        kind = kinds[fit.index] if fit.channel != "wrench" else "revolute"
        text = describe(fit, params, errs, reversals, kind)
        impossible = parameter_violations(params)
        if impossible:
            rejected.append((fit, f"{MODEL_WRONG}: {text} would need {'; '.join(impossible)}, which no joint has "
                                  "(not reported)"))
            continue
        worse = _made_worse(fit, channels, {f.index for f in fits if f.channel != "wrench"})
        if worse:
            rejected.append((fit, f"{text} (makes {', '.join(worse)} worse on the held-out rows by more than its "
                                  "noise: not accepted)"))
            continue
        # a load is there if its amplitude, or its torque or slope over the travel, is known
        unknown = load_unknown(fit, quiet.q[:, fit.index]) if fit.channel == "tau" else None
        # judged row by row or by its envelope or breakaway peaks alike: a size whose 95 % interval
        # holds zero is not known to be there (an effect-free recording was told "stiction 1.17
        # +- 3.4 N m" when the envelope fits skipped this)
        if uncertain(params, errs) and unknown is not False:
            rejected.append((fit, f"{text} (standard error larger than half the value: not reported)"))
            continue
        at = load_at_centre(fit, quiet.q[:, fit.index]) if unknown is False and uncertain(params, errs) else None
        if at is not None and abs(at[0]) > 2.0 * at[1]:
            # the load is there, its amplitude and angle are not pinned down: say what is known
            text += stroke_load_text(at, quiet.q[:, fit.index])
        if not fit.by_envelope and not confirmed(ch.rms_before, ch.rms_after):
            rejected.append((fit, f"{text} (the re-simulation with it does not lower the held-out {name} RMS: "
                                  f"{ch.rms_before:.3g} -> {ch.rms_after:.3g}; not reported)"))
            continue
        ch.significant = True
        if fit.by_envelope:
            # a ripple's phase or a slip's timing is not reproducible row by row: judge the fit
            # by its envelope or breakaway peaks
            ch.metric, ch.rms_before, ch.rms_after, ch.excess_after = \
                "envelope" if fit.judged_by == "samples" else fit.judged_by, fit.rms_heldout_before, \
                fit.rms_heldout_after, 0.0
        explained = max(fit.rms_heldout_before ** 2 - fit.rms_heldout_after ** 2, 0.0)
        alts = []
        if fit.channel == "tau":
            for alt in alternatives.get(fit.index, []):
                p, e = plant_parameters(alt)
                alts.append(describe(alt, p, e, reversals, kind).split(": ", 1)[1] +
                            _why_alike(quiet.dq[:, fit.index], kind, fit, alt))
            speed = stiction_unseparated(fit, quiet.dq[:, fit.index], alternatives.get(fit.index, []))
            if speed is not None:
                alts.append(STICTION_UNSEPARATED.format(speed=speed, unit=units_of(kind).velocity, events=reversals))
        findings.append(Finding(fit, explained / ch.noise ** 2, params, errs, text, _onset(t, before[name], ch.noise),
                                alts))
    return findings, rejected


FRICTION_LAWS = ("coulomb", "viscous", "stribeck")


def replayed_choice(fit: ChannelFit, alternatives: list[ChannelFit], table: RecordingTable, nominal: PlantConfig,
                    j: int, train: np.ndarray, velocity: np.ndarray) -> tuple[ChannelFit, list[ChannelFit]]:
    """Among friction laws the linear fit cannot tell apart (the chosen one and those named
    beside it as equally good), the one whose replay of the joint matches the recorded torque
    clearly best on the moving rows, each sized by its own replays first (sim_refit).

    The linear candidates are functions of the nominal motion, which has no friction: the real
    joint sticks at each reversal until the drive has wound up enough torque to break it free,
    and that breakaway peak, which Coulomb friction alone produces through the servo, is what
    a Stribeck bump fits in the linear view (Coulomb 36 N m on a slow ramp named stiction 39 N
    m, fading above 0.038 rad/s while the joint ran at 0.011 rad/s). The replay of each law
    reproduces how the joint sticks. Another law replaces the linear choice only where its
    replay's error is lower by MIN_CONFIRMED_REDUCTION: at 2-5x the noise on a one-speed ramp
    the replays of Coulomb and viscous friction differ by a few per cent either way, and the
    held-out rows alone (40 %) turned 11 % the wrong way (development seed 8301 case 4), so the
    error is taken over every moving row (the laws were sized on the training rows, the margin
    covers a second parameter's fit; the held-out rows must agree). Only single friction laws judged row by row take part."""
    from spacearm.offline.diagnosis.direct_sim import replayed_torque
    from spacearm.offline.diagnosis.honesty import MIN_CONFIRMED_REDUCTION
    single = lambda f: len(f.effects) == 1 and f.effects[0] in FRICTION_LAWS and f.judged_by == "samples" \
        and f.channel == "tau"
    others = [a for a in alternatives if single(a)]
    moving = np.abs(velocity) > VELOCITY_DEADBAND
    held = ~train & moving
    if fit.effects != ("stribeck",) or not moving.any() or \
            not fit.shape[0] > float(np.median(np.abs(velocity[moving]))):
        # only a Stribeck law fading above the joint's running speeds, whose bump is the servo's
        # breakaway peak: one that falls off within them shows what the running laws cannot, judged
        # at the breakaways (stick_slip.py). Between Coulomb and viscous friction the replays were
        # tried too and dropped: a running law that replays a stiction joint's breakaway peaks better
        # (Coulomb) took the place of the one stiction sits on, and the stiction was sized 25 % low
        return fit, alternatives
    if not single(fit) or not others or held.sum() < 10:
        return fit, alternatives
    def error(law: ChannelFit) -> tuple[float, float]:
        """RMS error of the law's replay on every moving row, and on the held-out ones."""
        tau = replayed_torque(apply_fits(nominal, [law]), table.q_cmd, table.dt, table.q[0], j, table.dq_cmd)
        if tau is None:
            return math.inf, math.inf
        r = table.tau[:, j] - tau
        return float(np.sqrt(np.mean(r[moving] ** 2))), float(np.sqrt(np.mean(r[held] ** 2)))
    best, (best_error, best_held) = fit, error(fit)
    # never towards more parameters: stiction is judged where it shows, by its breakaway (stick_slip,
    # stribeck_replay); sized by replays alone, a Stribeck law fading far above the running speed
    # is Coulomb friction by another name and won by the noise
    for alt in [a for a in others if a.n_params <= fit.n_params]:
        alt = replace(alt)       # sized by its own replays: a copy (the ranked list keeps the linear one)
        alt = refine_size(alt, nominal, table.q_cmd, table.dt, table.q[0], table.tau[:, j], train & moving,
                          apply_fits, table.dq_cmd)
        alt = refine_stiction(alt, nominal, table.q_cmd, table.dt, table.q[0], table.tau[:, j], train, apply_fits,
                              table.dq_cmd)
        e, e_held = error(alt)
        # ... and no worse on the held-out rows, which no law was sized on (a Stribeck law sized on
        # the training rows by two parameters beat Coulomb there by 13 % and lost on the held-out)
        if e < (1.0 - MIN_CONFIRMED_REDUCTION) * best_error and e_held <= best_held:
            best, best_error, best_held = alt, e, e_held
    if best is fit:
        return fit, alternatives
    return best, [fit if a.effects == best.effects else a for a in alternatives]


def _stiff_gear_wins(stiff: ChannelFit | None, fit: ChannelFit | None) -> bool:
    """A significant stiff-gear fit whose held-out torque error beats the joint's fit so far by
    STIFF_GEAR_BETTER (or there is none)."""
    # ... and whose size is known: one that is not is dropped later (honesty.uncertain), and had
    # it displaced the joint's fit, that fit was lost with it (viscous friction 3.4x the noise on
    # a slow ramp left "no catalogue effect" after a stiff gear of 2.1e5 +- 2.6e5 N m/rad beat it
    # by the noise)
    return stiff_significant(stiff) and (fit is None or stiff.rms_heldout_after < STIFF_GEAR_BETTER *
                                         fit.rms_heldout_after) and not uncertain(*plant_parameters(stiff))


MODEL_WRONG = "the model is wrong here"
SPEEDS_EXPERIMENT = ("the experiment that separates them: dwells at rest, then moves both ways at several speeds "
                     "from well below to several times this one (diagnose --run)")
STICTION_UNSEPARATED = ("stiction (Stribeck friction) falling to this running level: not separable from it on this "
                        "trajectory (at one speed, {speed:.3g} {unit}, the two differ only where the joint breaks "
                        "free, here at {events} reversal(s), and no breakaway stood above the noise there); "
                        + SPEEDS_EXPERIMENT)
GEAR_ALIKE = 1.25            # held-out envelope errors of backlash and elasticity within this ratio: alike
GEAR_EXPERIMENT = (" (both make the drive hunt and their envelopes fit alike; they differ in their signatures: "
                   "backlash is a dead band of fixed width at each reversal, elasticity a deflection that grows "
                   "with the load. To separate them: slow reversals under two different constant loads (a dead band "
                   "keeps its width, a deflection scales with the load), or a slow load ramp at rest)")


def _made_worse(fit: ChannelFit, channels: list[ChannelResult], fitted: set[int] | None = None) -> list[str]:
    """The channels whose held-out RMS the re-simulation with the fits raises by more than the
    channel's noise: a better torque bought with a worse position is no finding, and neither is
    one bought with another joint's worse error (a pooled gain hides a joint made worse). The
    fitted joint's own channels, and those of every joint with no fit of its own (`fitted`: the
    joints that have one; nothing but another joint's fit changed those)."""
    if fit.channel == "wrench" or fit.by_envelope:
        return []
    own = (f"q_{fit.index + 1}", f"tau_{fit.index + 1}")
    others = {f"{c}_{j + 1}" for j in range(len(channels)) for c in ("q", "tau")
              if fitted is not None and j not in fitted and j != fit.index}
    return [f"{c.name} {c.rms_before:.3g} -> {c.rms_after:.3g} (noise {c.noise:.2g})" for c in channels
            if (c.name in own or c.name in others) and c.rms_after > c.rms_before + c.noise]


def gear_alternatives(chosen: ChannelFit, gears: list[ChannelFit]) -> list[ChannelFit]:
    """The significant gear fits (`gears`) that explain the hunting about as well as the chosen
    one (held-out envelope error within GEAR_ALIKE): named beside it, never dropped."""
    if chosen not in gears:
        return []
    return [g for g in gears if g is not chosen and g.rms_heldout_after <= GEAR_ALIKE * chosen.rms_heldout_after]


def _why_alike(dq: np.ndarray, kind: str = "revolute", best: ChannelFit | None = None,
               alt: ChannelFit | None = None) -> str:
    from spacearm.offline.diagnosis.honesty import one_way, same_drag, single_speed
    if best is not None and alt is not None and {best.effects[0], alt.effects[0]} == set(GEAR_EFFECTS):
        return GEAR_EXPERIMENT
    if best is not None and alt is not None and same_drag(best, alt, dq):
        return (" (the joint moved one way only: a constant force along the axis and friction are the same drag "
                "there; they differ at reversals and at rest)")
    speed = single_speed(dq)
    if speed is not None:
        return (f" (the joint moved at one speed, about {speed:.3g} {units_of(kind).velocity}: these laws differ "
                f"only between speeds; {SPEEDS_EXPERIMENT})")
    if one_way(dq):
        return " (the joint moved one way only: the laws differ at reversals and starts from rest)"
    return " (the recording gives no strong evidence between them: BIC within 6)"


def ideal_sensors(config: PlantConfig) -> PlantConfig:
    ideal = {"resolver_arcsec": 0.0, "encoder_quantum": 0.0, "torque_noise": 0.0}
    joints = [j.model_copy(update=ideal) for j in config.joints]
    return config.model_copy(update={"joints": joints, "joint": config.joint.model_copy(update=ideal)})


def _stable_refit(table: RecordingTable, nominal: PlantConfig, fits: list[ChannelFit],
                  sim: SimTraces, replayed: bool = False) -> tuple[PlantConfig, SimTraces]:
    """Re-simulate with the fits; a fit whose plant does not simulate (diverges) is dropped
    (it is then not a credible explanation). `replayed`: `sim` is the direct replay of
    `nominal` (not a simulation the caller gave), so the unfitted joints are taken from it."""
    while fits:
        updated = apply_fits(nominal, fits)
        try:
            with np.errstate(all="raise"):
                refit = _replay_changed(table, updated, fits, sim) if replayed else replay(table, updated)
            if all(np.all(np.isfinite(x)) for x in (refit.q, refit.tau)):
                return updated, refit
        except (OverflowError, FloatingPointError, ValueError):
            pass
        fits.pop()          # the latest-added fit (gear effects and latency come after the simple ones)
    return nominal, sim


def _replay_changed(table: RecordingTable, updated: PlantConfig, fits: list[ChannelFit],
                    sim: SimTraces) -> SimTraces:
    """The replay of `updated` (the nominal of `sim` with the fits): only the fitted joints are
    simulated, the others are the nominal replay's own columns. Exact where the joints are
    independent and noise-free (a joint's torque noise draws from a generator numbered by its
    place in the simulated plant); otherwise every joint is replayed. Most of a diagnosis's
    replays are these, and most fits touch one or two joints of six or seven."""
    n = table.q.shape[1]
    joints = sorted({f.index for f in fits if f.channel != "wrench"})
    independent = updated.rigid_body is None and updated.contact is None and \
        all(updated.joint_params(j).torque_noise == 0.0 for j in range(n))
    if not independent or len(joints) == n:
        return replay(table, updated)
    part = simulate(updated, table.q_cmd, table.dt, q0=table.q[0], dq_cmd=table.dq_cmd, joints=joints or [0], t0=0.0)
    q, dq, tau = sim.q.copy(), sim.dq.copy(), sim.tau.copy()
    for c, j in enumerate(joints):
        q[:, j], dq[:, j], tau[:, j] = part.q[:, c], part.dq[:, c], part.tau[:, c]
    return SimTraces(sim.t.copy(), sim.q_cmd.copy(), q, dq, tau, part.wrench, part.following_error_max,
                     part.following_error_window)


def _channel_name(fit: ChannelFit) -> str:
    if fit.channel == "wrench":
        return WRENCH_COLUMNS[fit.index]
    return f"{fit.channel}_{fit.index + 1}"


def _channels(table: RecordingTable, nom: SimTraces, fitted: SimTraces):
    for j in range(table.q.shape[1]):
        yield f"q_{j + 1}", table.q[:, j], nom.q[:, j], fitted.q[:, j]
        yield f"tau_{j + 1}", table.tau[:, j], nom.tau[:, j], fitted.tau[:, j]
    for i, name in enumerate(WRENCH_COLUMNS):
        yield name, table.wrench[:, i], nom.wrench[:, i], fitted.wrench[:, i]
