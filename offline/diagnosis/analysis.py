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
from dataclasses import dataclass, field

import numpy as np

from spacearm.offline.diagnosis.candidates import (FT_CANDIDATES, JOINT_CANDIDATES, TORQUE_PAIRS, VELOCITY_DEADBAND, Signals,
                                            by_name)
from spacearm.offline.diagnosis.direct_sim import SimTraces, simulate
from spacearm.offline.diagnosis.fitting import ChannelFit, common_block, fit_candidate, fit_pair
from spacearm.offline.diagnosis.gear_effects import GEAR_EFFECTS, envelope, fit_gear_effect
from spacearm.offline.diagnosis.recording_io import RecordingTable
from spacearm.offline.diagnosis.sim_refit import refine_size
from spacearm.controller.recording.csv_export import WRENCH_COLUMNS
from spacearm.firmware_sim.plant import ARCSEC, PlantConfig

TRAIN_FRACTION = 0.6


@dataclass
class Finding:
    fit: ChannelFit
    score: float                 # explained variance (held-out) over noise variance
    params: dict[str, float]     # plant parameters (SI)
    stderr: dict[str, float]
    text: str
    onset: float | None = None   # first change point of the channel's residual, s


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

    @property
    def unexplained(self) -> list[ChannelResult]:
        return [c for c in self.channels if c.unexplained]

    @property
    def verdict(self) -> str:
        if not self.findings and not self.unexplained:
            return "no significant mismatch between the recording and the nominal simulation"
        words = [f.text for f in self.findings]
        if self.unexplained:
            words.append("mismatch no catalogue effect explains on " + ", ".join(
                f"{c.name} ({c.excess_after:.1f}x the significance threshold)" for c in self.unexplained))
        return "; ".join(words)


def noise_level(residual: np.ndarray) -> float:
    """Row-to-row scatter of a residual (std of differences / sqrt 2). Not a robust (MAD)
    estimate on purpose: resolver chatter makes sparse torque spikes of Kp x one quantum
    that belong to the noise, not to a physical effect."""
    return float(np.std(np.diff(residual)) / math.sqrt(2.0)) + 1e-12


RAW_RATIO_LIMIT = 1.5      # residual RMS / noise: 1.0-1.3 without any effect (measured, random starts)
SMOOTH_RATIO_LIMIT = 0.6   # 0.5 s moving-average RMS / noise: 0.2-0.45 without any effect


NULL_MARGIN = 2.0          # one draw of the null replay's average, scattered up to about 1.7x (measured)
HUNTING_RATIO = 5.0        # residual RMS / median noise of the torque channels: a drive that hunts


def smoothed_rms(residual: np.ndarray, window: int = 25) -> float:
    """RMS of the residual's moving average over `window` rows (0.5 s at 50 Hz)."""
    return float(np.sqrt(np.mean(np.convolve(residual, np.ones(window) / window, mode="valid") ** 2)))


def mismatch_statistic(residual: np.ndarray, noise_floor: float, window: int = 25,
                       reference_noise: float | None = None, null_smooth: float = 0.0) -> float:
    """How far a residual is from noise, as a multiple of the limit (> 1: significant).

    Two views: the raw RMS against the row-to-row noise (catches ringing and hunting) and the
    0.5 s average (catches slow offsets hidden in noise). The limits hold for the servo's
    resolver chatter, which is not white; measured on effect-free recordings. `null_smooth`
    is the 0.5 s average RMS between two equally valid nominal replays (see null_replay):
    where the arm rests, the servo parks anywhere within a resolver quantum, and that
    offset, not the chatter, sets what the average shows without any effect."""
    noise = max(noise_level(residual), noise_floor)
    raw = float(np.sqrt(np.mean(residual ** 2))) / noise
    smooth = smoothed_rms(residual, window)
    stat = max(raw / RAW_RATIO_LIMIT, smooth / max(SMOOTH_RATIO_LIMIT * noise, NULL_MARGIN * null_smooth))
    if reference_noise:
        # dense ringing (a hunting drive) inflates the channel's own row-to-row noise estimate:
        # compare with the noise the other channels of the same kind show
        stat = max(stat, float(np.sqrt(np.mean(residual ** 2))) / reference_noise / HUNTING_RATIO)
    return stat


def replay(table: RecordingTable, plant: PlantConfig, joints: list[int] | None = None) -> SimTraces:
    return simulate(plant, table.q_cmd, table.dt, q0=table.q[0], joints=joints, t0=0.0)


def null_replay(table: RecordingTable, plant: PlantConfig) -> SimTraces:
    """The nominal replay from half a resolver quantum away: the recording's first position
    is only known to a quantum, so this replay is as valid as the other, and how much the
    two differ is what the recording may differ from either without any missing physics."""
    n = table.q.shape[1]
    quantum = np.array([(plant.joints[j] if j < len(plant.joints) else plant.joint).resolver_arcsec
                        for j in range(n)]) * ARCSEC
    return simulate(plant, table.q_cmd, table.dt, q0=table.q[0] + 0.5 * quantum, t0=0.0)


def _signals(table: RecordingTable, sim: SimTraces, j: int) -> Signals:
    t = table.t - table.t[0]
    return Signals(t, sim.q[:, j], sim.dq[:, j], sim.tau[:, j], table.dt)


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
                 train: np.ndarray) -> list[ChannelFit]:
    """Significant torque-channel explanations of joint j, best first."""
    s = _signals(table, quiet, j)
    y = table.tau[:, j] - sim.tau[:, j]
    # Rows where the nominal joint rests are left out of the fits: with static friction the
    # real joint sticks wherever break-away left it, a torque offset no smooth model predicts
    # and that, kept in, only dilutes the rows where friction shows (and the noise estimate).
    fit_rows = train & (np.abs(s.dq) > VELOCITY_DEADBAND)
    if fit_rows.sum() < 0.2 * train.sum():
        fit_rows = train
    held = ~train
    fits = {c.effect: fit_candidate(c, s, y, fit_rows, j, held) for c in JOINT_CANDIDATES if c.channel == "tau"}
    ranked = _ranked(list(fits.values()))
    if not ranked:
        return []
    best = ranked[0]
    pairs = []
    for a, b in TORQUE_PAIRS:
        if best.effects[0] in (a, b):
            pairs.append(fit_pair(by_name(a), by_name(b), s, y, fit_rows, j, fits[a].shape[0], fits[b].shape[0],
                                  held))
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


def _reversals(v: np.ndarray) -> int:
    """Velocity sign changes between real motions (a quarter of the top speed: the servo's
    settling wiggle from the first measured position is no reversal)."""
    moving = v[np.abs(v) > max(VELOCITY_DEADBAND, 0.25 * float(np.max(np.abs(v))))]
    return int(np.count_nonzero(np.diff(np.sign(moving))))


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


def diagnose(table: RecordingTable, nominal: PlantConfig, sim: SimTraces | None = None) -> Diagnosis:
    timings = {}
    started = time.perf_counter()
    n_rows, n = table.q.shape
    if sim is None:
        sim = replay(table, nominal)
    timings["replay_s"] = time.perf_counter() - started
    train = np.zeros(n_rows, bool)
    train[: int(TRAIN_FRACTION * n_rows)] = True
    t = table.t - table.t[0]

    fits: list[ChannelFit] = []
    # Candidate features come from a replay with ideal resolvers: a feature built from the
    # nominal replay's own quantisation chatter would "explain" the chatter in the residual.
    quiet = replay(table, ideal_sensors(nominal))
    tau_noise = float(np.median([noise_level(table.tau[:, j] - sim.tau[:, j]) for j in range(n)]))
    for j in range(n):
        fit = next((f for f in _torque_fits(table, sim, quiet, j, train) if _simulates(table, nominal, f)), None)
        if fit is not None:
            fit = refine_size(fit, nominal, table.q_cmd, table.dt, table.q[0], table.tau[:, j],
                              train & (np.abs(quiet.dq[:, j]) > VELOCITY_DEADBAND), apply_fits)
        residual = table.tau[:, j] - sim.tau[:, j]
        left = residual if fit is None else residual - fit.prediction
        if mismatch_statistic(left, 1e-3, reference_noise=tau_noise) > 1.0 and \
                float(np.sqrt(np.mean(left ** 2))) > HUNTING_RATIO * tau_noise:
            # the drive hunts or rings: try the gear effects (simulated, compared by envelope)
            for effect in GEAR_EFFECTS:
                gear = fit_gear_effect(effect, nominal, table.q_cmd, table.dt, table.q[0], quiet.tau[:, j], residual,
                                       tau_noise, j, train)
                if gear.significant and (fit is None or gear.rms_heldout_after < 0.7 * _envelope_error(
                        fit, residual, tau_noise, ~train)):
                    fit = gear
        if fit is not None:
            fits.append(fit)
    for axis in range(6):
        fit = _ft_fit(table, sim, axis, train)
        if fit is not None:
            fits.append(fit)
    timings["fit_s"] = time.perf_counter() - started - timings["replay_s"]

    updated, refit = _stable_refit(table, nominal, fits, sim)
    for j in range(n):
        fit = _latency_fit(table, refit, j, train)
        if fit is not None:
            fits.append(fit)
    if any(f.effects == ("latency",) for f in fits):
        updated, refit = _stable_refit(table, nominal, fits, sim)
    timings["refit_s"] = time.perf_counter() - started - timings["replay_s"] - timings["fit_s"]

    held = ~train
    channels, before, after = [], {}, {}
    quantum = [(nominal.joints[j] if j < len(nominal.joints) else nominal.joint).resolver_arcsec * ARCSEC
               for j in range(n)]
    ref = {"ta": tau_noise}
    null = dict((name, real - nom) for name, real, nom, _ in _channels(null_replay(table, nominal), sim, sim))
    for name, real, nom, fitted in _channels(table, sim, refit):
        r0, r1 = real - nom, real - fitted
        null_smooth = smoothed_rms(null[name])
        before[name], after[name] = r0, r1
        floor = (quantum[int(name[2:]) - 1] if name.startswith("q_") else 0.01 if name.startswith("f") else 0.001) \
            / math.sqrt(12.0) if not name.startswith("tau") else 1e-3
        channels.append(ChannelResult(name, max(noise_level(r0), floor), float(np.sqrt(np.mean(r0[held] ** 2))),
                                      float(np.sqrt(np.mean(r1[held] ** 2))), False,
                                      mismatch_statistic(r0, floor, reference_noise=ref.get(name[:2]),
                                                         null_smooth=null_smooth),
                                      mismatch_statistic(r1, floor, reference_noise=ref.get(name[:2]),
                                                         null_smooth=null_smooth)))
    findings = []
    for fit in fits:
        name = _channel_name(fit)
        ch = next(c for c in channels if c.name == name)
        ch.significant = True
        if fit.by_envelope:
            # the ripple's phase is not reproducible row by row: judge the fit by its envelope
            ch.metric, ch.rms_before, ch.rms_after, ch.excess_after = \
                "envelope", fit.rms_heldout_before, fit.rms_heldout_after, 0.0
        explained = max(fit.rms_heldout_before ** 2 - fit.rms_heldout_after ** 2, 0.0)
        params, errs = plant_parameters(fit)
        reversals = _reversals(quiet.dq[:, fit.index]) if fit.channel == "tau" else None
        findings.append(Finding(fit, explained / ch.noise ** 2, params, errs, describe(fit, params, errs, reversals),
                                _onset(t, before[name], ch.noise)))
    findings.sort(key=lambda f: -f.score)
    timings["total_s"] = time.perf_counter() - started
    return Diagnosis(findings, channels, updated, float(t[int(TRAIN_FRACTION * n_rows)]), timings, before, after, t)


def ideal_sensors(config: PlantConfig) -> PlantConfig:
    joints = [j.model_copy(update={"resolver_arcsec": 0.0, "torque_noise": 0.0}) for j in config.joints]
    return config.model_copy(update={"joints": joints, "joint": config.joint.model_copy(
        update={"resolver_arcsec": 0.0, "torque_noise": 0.0})})


def _stable_refit(table: RecordingTable, nominal: PlantConfig, fits: list[ChannelFit],
                  sim: SimTraces) -> tuple[PlantConfig, SimTraces]:
    """Re-simulate with the fits; a fit whose plant does not simulate (diverges) is dropped
    (it is then not a credible explanation)."""
    while fits:
        updated = apply_fits(nominal, fits)
        try:
            with np.errstate(all="raise"):
                refit = replay(table, updated)
            if all(np.all(np.isfinite(x)) for x in (refit.q, refit.tau)):
                return updated, refit
        except (OverflowError, FloatingPointError, ValueError):
            pass
        fits.pop()          # the latest-added fit (gear effects and latency come after the simple ones)
    return nominal, sim


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


# ---------------------------------------------------------------- parameters and words
def plant_parameters(fit: ChannelFit) -> tuple[dict[str, float], dict[str, float]]:
    """Fitted coefficients as plant-file parameters (SI) with standard errors."""
    p, e = {}, {}
    coef = dict(zip(fit.columns, fit.coef))
    err = dict(zip(fit.columns, fit.stderr))
    for effect, shape in zip(fit.effects, fit.shape):
        if effect in ("coulomb", "viscous"):
            key = f"{effect}_friction"
            p[key], e[key] = float(coef[key]), float(err[key])
        elif effect == "stribeck":
            p["stribeck_friction"], e["stribeck_friction"] = float(coef["stribeck_friction"]), \
                float(err["stribeck_friction"])
            p["stribeck_velocity"] = float(shape)
        elif effect == "gravity_load":
            c, s = coef["load_cos"], coef["load_sin"]
            amp = float(math.hypot(c, s))
            p["gravity_torque"], p["gravity_angle"] = amp, float(math.atan2(s, c))
            e["gravity_torque"] = float(math.hypot(err["load_cos"], err["load_sin"]) / math.sqrt(2))
        elif effect == "torque_saturation":
            p["torque_limit_joint"] = float(shape)
        elif effect == "latency":
            p["feedback_latency_cycles"] = int(shape)
        elif effect in GEAR_EFFECTS:
            key = GEAR_EFFECTS[effect][0]
            p[key], e[key] = float(fit.coef[0]), float(fit.stderr[0])
        elif effect == "ft_bias":
            p["bias"], e["bias"] = float(coef["bias"]), float(err["bias"])
        elif effect == "ft_drift":
            p["bias"], e["bias"] = float(coef["bias"]), float(err["bias"])
            p["drift"], e["drift"] = float(coef["drift"]), float(err["drift"])
    return p, e


def describe(fit: ChannelFit, p: dict[str, float], e: dict[str, float], reversals: int | None = None) -> str:
    """The finding in a test engineer's words. `reversals`: velocity sign changes of the
    joint in the recording; without any, friction laws cannot be told apart (each is a
    constant drag at constant speed) and the text says so."""
    where = f"joint {fit.index + 1}" if fit.channel != "wrench" else f"F/T {WRENCH_COLUMNS[fit.index]}"
    unit = "N" if fit.index < 3 else "N m"
    parts = []
    pm = lambda k: f" +- {e[k]:.2g}" if k in e and np.isfinite(e[k]) else ""
    for effect in fit.effects:
        if effect == "coulomb":
            parts.append(f"Coulomb friction about {p['coulomb_friction']:.3g}{pm('coulomb_friction')} N m, " + (
                "a constant drag (no velocity reversal in this recording: Coulomb, Stribeck and viscous friction "
                "look alike here)" if reversals == 0 else "visible at every velocity reversal"))
        elif effect == "viscous":
            parts.append(f"viscous friction about {p['viscous_friction']:.3g}{pm('viscous_friction')} N m s/rad, "
                         "growing with speed")
        elif effect == "stribeck":
            parts.append(f"stiction (Stribeck) {p['stribeck_friction']:.3g}{pm('stribeck_friction')} N m above "
                         f"running friction, fading above about {p['stribeck_velocity']:.3g} rad/s: visible when "
                         "the joint starts from rest")
        elif effect == "gravity_load":
            parts.append(f"unmodelled load torque (gravity / payload mass) {p['gravity_torque']:.3g}"
                         f"{pm('gravity_torque')} N m, depending on position, peak at q = "
                         f"{math.degrees(-p['gravity_angle']):.0f} deg")
        elif effect == "torque_saturation":
            parts.append(f"drive torque saturates at about {p['torque_limit_joint']:.3g} N m (joint side) in the "
                         "fastest accelerations")
        elif effect == "latency":
            n = p["feedback_latency_cycles"]
            parts.append(f"position feedback arrives {n} cycle{'s' if n > 1 else ''} late ({20 * n} ms at 50 Hz)")
        elif effect == "backlash":
            err = e.get("backlash", float("nan"))
            unc = f" +- {1e3 * err:.1g}" if np.isfinite(err) else ""
            parts.append(f"backlash (play in the gear) about {1e3 * p['backlash']:.2g}{unc} mrad: the drive hunts, "
                         "torque ripple the nominal model lacks")
        elif effect == "elasticity":
            parts.append(f"elastic gear, stiffness about {p['joint_stiffness']:.3g}{pm('joint_stiffness')} N m/rad: "
                         "the drive rings, torque ripple the nominal model lacks")
        elif effect == "ft_bias":
            parts.append(f"constant offset {p['bias']:.3g}{pm('bias')} {unit}")
        elif effect == "ft_drift":
            parts.append(f"offset drifting by {60 * p['drift']:.3g} {unit} per minute (from {p['bias']:.3g} {unit})")
    return f"{where}: " + " and ".join(parts)


def apply_fits(nominal: PlantConfig, fits: list[ChannelFit]) -> PlantConfig:
    """A copy of the nominal plant with the fitted effects switched on."""
    n = max([len(nominal.joints)] + [f.index + 1 for f in fits if f.channel != "wrench"])
    joints = [nominal.joints[i] if i < len(nominal.joints) else nominal.joint for i in range(n)]
    bias, drift = list(nominal.ft.bias), list(nominal.ft.drift)
    for fit in fits:
        p, _ = plant_parameters(fit)
        if fit.channel == "wrench":
            bias[fit.index] += p.get("bias", 0.0)
            drift[fit.index] += p.get("drift", 0.0)
            continue
        update = {}
        for key, value in p.items():
            if key == "torque_limit_joint":
                update["torque_limit"] = value / joints[fit.index].gear_ratio
            elif key in ("coulomb_friction", "viscous_friction", "stribeck_friction", "gravity_torque"):
                update[key] = max(0.0, value)
            else:
                update[key] = value
        joints[fit.index] = joints[fit.index].model_copy(update=update)
    return nominal.model_copy(update={"joints": joints,
                                      "ft": nominal.ft.model_copy(update={"bias": tuple(bias), "drift": tuple(drift)})})
