"""Diagnosis of a torque recording of the user's own arm against its rigid-body model (URDF).

The ORU simulator replays commands through our drives; a recording of another arm was made
by its own drives, so here the nominal model is the URDF's inverse dynamics on the measured
motion (q, the recorded dq, and q'' from a zero-phase low-pass), and the torque residual is
explained by the catalogue:

- per joint: Coulomb and viscous friction, a constant torque offset, Stribeck friction
  (chosen by BIC on the training rows, block-corrected, see fitting.fit_features);
- coupled: rigid-body parameter errors through the base parameters (all joints at once),
  named as a payload on the last link when that alone explains as much.

Every finding must lower the held-out RMS of its joint (rows from `heldout_from` on); each
joint's before/after is reported beside the nominal model's.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.signal import butter, filtfilt

from spacearm.offline.diagnosis.candidates import STRIBECK_VELOCITIES, VELOCITY_DEADBAND
from spacearm.offline.diagnosis.fitting import SIGNIFICANCE, ChannelFit, fit_features
from spacearm.offline.diagnosis.honesty import MIN_CONFIRMED_REDUCTION, moved, single_speed, uncertain
from spacearm.offline.diagnosis.joint_units import units_of
from spacearm.offline.diagnosis.physical import (from_log_cholesky, levenberg_marquardt, log_cholesky_jacobian,
                                                parameter_violations, to_log_cholesky)
from spacearm.offline.diagnosis.recording_io import RecordingTable
from spacearm.offline.diagnosis.rigid_body import ArmModel, base_columns, inverse_dynamics, regressor
from spacearm.offline.diagnosis.sensor_effects import SensorFinding, sensor_findings
from spacearm.offline.diagnosis.torque_alignment import TimeOffset, shifted, torque_time_offset
from spacearm.offline.diagnosis.velocity_clock import VelocityLag, velocity_lag

LOWPASS_HZ = 20.0            # q'' from dq: 4th-order Butterworth, zero phase (as Gaz et al. suggest)
# friction laws tried per joint (features side by side), simplest first
FRICTION_SETS = (("offset",), ("coulomb",), ("viscous",), ("coulomb", "viscous"), ("coulomb", "offset"),
                 ("viscous", "offset"), ("coulomb", "viscous", "offset"), ("stribeck", "coulomb", "viscous", "offset"))
COLUMN = {"offset": "torque_offset", "coulomb": "coulomb_friction", "viscous": "viscous_friction",
          "stribeck": "stribeck_friction"}
ROUNDS = 2                   # friction / rigid-body alternations
PAYLOAD_SHARE = 0.8          # a payload explaining this share of the base-parameter refit's variance is named
PHYSICAL_SHARE = 0.5         # real bodies must explain this share of what unconstrained base parameters do
ON_BOUND = 0.02              # a last link left with less than this share of its mass: the fit sits on its bound
PHYSICAL_FIT_ITERATIONS = 60


@dataclass
class JointTorque:
    joint: int                       # 0-based
    moved: bool
    rms_nominal: float               # held-out, rigid-body model only
    rms_fitted: float                # held-out, with the reported findings
    noise: float
    kind: str = "revolute"           # prismatic: the channel is a force, N


@dataclass
class ArmFinding:
    effects: tuple[str, ...]
    joint: int | None                # None: coupled (rigid body)
    params: dict[str, float]
    stderr: dict[str, float]
    text: str
    heldout_reduction: float         # on its joint(s), by the re-evaluated model


@dataclass
class ArmDiagnosis:
    findings: list[ArmFinding]
    joints: list[JointTorque]
    heldout_start: float
    not_reported: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    sensor_findings: list[SensorFinding] = field(default_factory=list)
    model_wrong: list[str] = field(default_factory=list)     # fits that needed a physically impossible value
    time_offset: TimeOffset | None = None                    # torque vs motion columns, re-aligned before fitting
    velocity_lag: VelocityLag | None = None                  # dq vs dq/dt(q): named, not re-aligned (velocity_clock)

    @property
    def to_excite(self) -> list[int]:
        """Joints (0-based) an experiment should move: those whose friction laws looked alike
        (one speed), else those that did not move."""
        alike = [f.joint for f in self.findings if f.joint is not None and "look alike" in f.text]
        return alike or [j.joint for j in self.joints if not j.moved]

    @property
    def verdict(self) -> str:
        offset = ([self.time_offset.text] if self.time_offset else []) + (
            [self.velocity_lag.text] if self.velocity_lag else [])
        if not self.findings and not self.sensor_findings and not self.model_wrong and not offset:
            return "no significant torque mismatch against the rigid-body model"
        return "; ".join(offset + [s.text for s in self.sensor_findings] + [f.text for f in self.findings]
                         + self.model_wrong)


def accelerations(table: RecordingTable) -> tuple[np.ndarray, np.ndarray]:
    """(dq, ddq): the recorded dq when there is one (else dq/dt of q), low-passed, and its derivative."""
    dt = table.dt
    dq = table.dq if np.any(table.dq) else np.gradient(table.q, dt, axis=0)
    cutoff = min(LOWPASS_HZ, 0.4 / dt)
    if len(table.t) > 30:
        b, a = butter(4, cutoff * 2 * dt)
        dq_f = filtfilt(b, a, dq, axis=0)
    else:
        dq_f = dq
    return dq_f, np.gradient(dq_f, dt, axis=0)


def _features(effect: str, v: np.ndarray, shape: float) -> np.ndarray:
    sign = np.where(np.abs(v) > VELOCITY_DEADBAND, np.sign(v), 0.0)
    if effect == "offset":
        return np.ones_like(v)
    if effect == "coulomb":
        return sign
    if effect == "viscous":
        return v
    return sign * np.exp(-(v / shape) ** 2)


def _fit_set(effects: tuple[str, ...], v: np.ndarray, y: np.ndarray, train: np.ndarray, j: int) -> ChannelFit:
    grid = STRIBECK_VELOCITIES if "stribeck" in effects else (math.nan,)
    best = None
    for vs in grid:
        X = np.column_stack([_features(e, v, vs) for e in effects])
        fit = fit_features(effects, "tau", j, tuple(COLUMN[e] for e in effects),
                           tuple(vs if e == "stribeck" else math.nan for e in effects), X, y, train)
        if best is None or fit.sse_train < best.sse_train:
            best = fit
    return best


def friction_fit(v: np.ndarray, y: np.ndarray, train: np.ndarray, j: int) -> tuple[ChannelFit | None, list]:
    """The best significant friction/offset law of one joint (lowest BIC at one block length),
    and the others ranked (for ambiguity)."""
    # the held-out bar is the confirmation one (5 %): on a real arm a friction of 0.2 N m is a
    # small part of a residual that modelling errors elsewhere dominate, yet plainly there
    fits = [f for f in (_fit_set(s, v, y, train, j) for s in FRICTION_SETS)
            if f.p_value < SIGNIFICANCE and f.heldout_reduction >= MIN_CONFIRMED_REDUCTION]
    if not fits:
        return None, []
    block = min(fits, key=lambda f: f.sse_train).block
    fits.sort(key=lambda f: f.bic_at(block))
    # a set whose sizes the recording cannot pin down (Coulomb beside viscous at one speed:
    # the block jackknife shows them swinging against each other) gives way to the next best
    known = [f for f in fits if not uncertain(dict(zip(f.columns, f.coef)), dict(zip(f.columns, f.stderr)))]
    best = known[0] if known else fits[0]
    return best, [f for f in fits if f is not best]


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x ** 2))) if len(x) else 0.0


def joint_kinds(arm: ArmModel) -> list[str]:
    """Each joint's kind from the URDF model (Pinocchio's prismatic joints: PX, PY, PZ,
    PrismaticUnaligned)."""
    return ["prismatic" if arm.model.joints[i].shortname().startswith("JointModelP") else "revolute"
            for i in range(1, arm.model.njoints)]


def _describe_friction(fit: ChannelFit, v: np.ndarray, kind: str = "revolute") -> tuple[str, dict, dict]:
    u = units_of(kind)
    p = {c: float(x) for c, x in zip(fit.columns, fit.coef)}
    e = {c: float(x) for c, x in zip(fit.columns, fit.stderr)}
    words = []
    for effect, col, shape in zip(fit.effects, fit.columns, fit.shape):
        pm = f" +- {1.96 * e[col]:.2g}"
        if effect == "coulomb":
            words.append(f"Coulomb friction {p[col]:.3g}{pm} {u.effort}")
        elif effect == "viscous":
            words.append(f"viscous friction {p[col]:.3g}{pm} {u.damping}")
        elif effect == "offset":
            words.append(f"{'force' if kind == 'prismatic' else 'torque'} offset {p[col]:.3g}{pm} {u.effort}")
        else:
            p["stribeck_velocity"] = float(shape)
            words.append(f"stiction (Stribeck) {p[col]:.3g}{pm} {u.effort} fading above {shape:.3g} {u.velocity}")
    text = f"joint {fit.index + 1}: " + " and ".join(words) + " (95 % intervals)"
    speed = single_speed(v)
    if speed is not None and {"coulomb", "viscous"} & set(fit.effects):
        text += (f"; the joint moved at one speed (about {speed:.3g} {u.velocity}): Coulomb and viscous friction "
                 "look alike")
    return text, p, e


def _payload_columns(arm: ArmModel) -> list[int]:
    last = arm.n - 1
    return [10 * last + k for k in range(10)]     # mass, first moments and inertia of the last link


def _physical_refit(arm: ArmModel, Y: np.ndarray, y: np.ndarray, train: np.ndarray, active: list[int],
                    links: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """(change of every link's ten parameters, predicted torque change on the active joints):
    least squares over the `links`' log-Cholesky numbers (see physical), so every answer is a
    set of real bodies. Directions the recording does not identify stay at the URDF's values
    (a weak pull toward them)."""
    nominal = [_link(arm, i) for i in links]
    theta0 = np.concatenate([to_log_cholesky(p) for p in nominal])
    cols = [10 * i + k for i in links for k in range(10)]
    rows = Y[train][:, active][:, :, cols].reshape(-1, len(cols))
    # the model is linear in the parameter change: ||rows d - y||^2 = ||A d - b||^2 + const with
    # A'A = rows'rows (from its eigen-decomposition), so the nonlinear fit runs on a square system
    values, vectors = np.linalg.eigh(rows.T @ rows)
    values = np.clip(values, 1e-12 * max(float(values.max()), 1e-300), None)
    A = np.sqrt(values)[:, None] * vectors.T
    b = (vectors.T @ (rows.T @ y[train].reshape(-1))) / np.sqrt(values)
    weight = 1e-2 * max(float(np.sqrt(np.mean(y[train] ** 2))), 1e-9)

    def change(theta: np.ndarray) -> np.ndarray:
        return np.concatenate([from_log_cholesky(theta[10 * k: 10 * k + 10]) - nominal[k] for k in range(len(links))])

    def jacobian(theta: np.ndarray) -> np.ndarray:
        blocks = [A[:, 10 * k: 10 * k + 10] @ log_cholesky_jacobian(theta[10 * k: 10 * k + 10])
                  for k in range(len(links))]
        return np.vstack([np.hstack(blocks), weight * np.eye(len(theta0))])

    theta = levenberg_marquardt(lambda th: np.r_[A @ change(th) - b, weight * (th - theta0)], jacobian, theta0,
                                PHYSICAL_FIT_ITERATIONS)
    delta = np.zeros(Y.shape[-1])
    delta[cols] = change(theta)
    return delta, np.einsum("rjc,c->rj", Y[:, active], delta)


def _link(arm: ArmModel, i: int) -> np.ndarray:
    """Link i's (0-based joint) ten dynamic parameters in the URDF (any locked fingers folded in)."""
    return np.asarray(arm.model.inertias[i + 1].toDynamicParameters(), float)


def _rigid_body_fit(arm: ArmModel, Y: np.ndarray, cols: list[int], left: np.ndarray, train: np.ndarray,
                    active: list[int]):
    """(correction, description or None, why the model is wrong or None): the payload on the
    last link when it explains most of what a refit of every link does, else that refit, else
    nothing. Both are fitted as real bodies (see _physical_refit); a payload that needs the
    last link at its bound (no mass left), or torques that only an unconstrained refit of the
    base parameters explains, mean the rigid-body model is wrong here, not a finding."""
    rb = np.zeros_like(left)
    if not cols or not active:
        return rb, None, None
    y = left[:, active]
    base = _rms(y[~train])

    def gain_of(pred: np.ndarray) -> float:
        return 1 - _rms((y - pred)[~train]) / max(base, 1e-12)

    Yc = Y[:, active][:, :, cols]
    coef, *_ = np.linalg.lstsq(Yc[train].reshape(-1, len(cols)), y[train].reshape(-1), rcond=None)
    free_gain = gain_of(np.einsum("rjc,c->rj", Yc, coef))
    if free_gain < MIN_CONFIRMED_REDUCTION:
        return rb, None, None
    delta, full_pred = _physical_refit(arm, Y, y, train, active, list(range(arm.n)))
    gain = gain_of(full_pred)
    last = arm.n - 1
    dp, pay_pred = _physical_refit(arm, Y, y, train, active, [last])
    dp = dp[10 * last: 10 * last + 10]
    pay_gain = gain_of(pay_pred)
    nominal = _link(arm, last)
    share = lambda g: 1 - (1 - max(g, 0.0)) ** 2       # compared as shares of the explained variance
    if share(pay_gain) >= PAYLOAD_SHARE * share(gain) and pay_gain >= MIN_CONFIRMED_REDUCTION and abs(dp[0]) > 1e-3:
        c = dp[1:4] / dp[0]
        where = f"{dp[0]:+.3g} kg at ({c[0]:.3g}, {c[1]:.3g}, {c[2]:.3g}) m in {arm.joint_names[-1]}'s frame"
        if nominal[0] + dp[0] < ON_BOUND * nominal[0]:
            return rb, None, (
                f"the rigid-body model is wrong here: the torques ask for a last link lighter than no mass (a payload "
                f"/ last-link mass error {where}, {nominal[0]:.3g} kg nominal: the fit sits at zero mass) - no "
                "physical body; look for a torque scale (gear ratio, torque constant) or sign error, or an effect "
                "the catalogue lacks")
        rb[:, active] = pay_pred
        return rb, (f"payload / last-link mass error {where} (fitted as a real body; a refit of every link would "
                    f"explain {100 * gain:.0f} % of the held-out torque RMS, the payload {100 * pay_gain:.0f} %)",
                    {"payload_mass": float(dp[0]), "payload_com_x": float(c[0]), "payload_com_y": float(c[1]),
                     "payload_com_z": float(c[2]), "last_link_total_mass": float(nominal[0] + dp[0])},
                    pay_gain, ("payload",)), None
    if gain < MIN_CONFIRMED_REDUCTION or share(gain) < PHYSICAL_SHARE * share(free_gain):
        return rb, None, (
            f"the rigid-body model is wrong here: a refit of its {len(cols)} base parameters with no physical "
            f"constraint would explain {100 * free_gain:.0f} % of the held-out torque RMS, real bodies only "
            f"{100 * gain:.0f} % - look for a torque scale or sign error, or an effect the catalogue lacks")
    arm_mass = sum(_link(arm, i)[0] for i in range(arm.n))
    implausible = [f"{arm.joint_names[i]} {delta[10 * i]:+.3g} kg" for i in range(arm.n)
                   if abs(delta[10 * i]) > arm_mass]
    if implausible:
        # a body, but not this arm: a link heavier by more than the whole arm is a scale or sign error
        return rb, None, (
            f"the rigid-body model is wrong here: real bodies explain {100 * gain:.0f} % of the held-out torque RMS "
            f"only with link mass changes larger than the whole arm ({arm_mass:.3g} kg): {', '.join(implausible)} - "
            "look for a torque scale (gear ratio, torque constant) or sign error, or an effect the catalogue lacks")
    masses = [f"{arm.joint_names[i]} {delta[10 * i]:+.2g} kg" for i in range(arm.n) if abs(delta[10 * i]) > 1e-2]
    rb[:, active] = full_pred
    return rb, (f"rigid-body parameters differ from the URDF: every link refitted as a real body (held-out torque "
                f"RMS {100 * gain:.0f} % lower on the moving joints, unconstrained base parameters "
                f"{100 * free_gain:.0f} %; a payload alone: {100 * pay_gain:.0f} %)"
                + (f"; mass changes {', '.join(masses)}" if masses else ""),
                {"base_parameters": float(len(cols))} | {f"mass_change_{name}": float(delta[10 * i])
                                                          for i, name in enumerate(arm.joint_names)},
                gain, ("rigid_body",)), None


def _made_worse(r: np.ndarray, model: np.ndarray, rb: np.ndarray, train: np.ndarray, noise: list[float],
                active: list[int]) -> list[str]:
    """The joints a rigid-body correction makes worse on the held-out rows by more than their
    noise, in words: a pooled gain on the heavy joints may hide a wrist made 10x worse."""
    worse = []
    for j in active:
        before, after = _rms((r - model)[~train, j]), _rms((r - model - rb)[~train, j])
        if after > before + noise[j]:
            worse.append(f"tau_{j + 1} {before:.3g} -> {after:.3g} (noise {noise[j]:.2g})")
    return worse


def _friction_fits(v: np.ndarray, left: np.ndarray, train: np.ndarray, active: list[int]
                   ) -> tuple[dict[int, ChannelFit], np.ndarray]:
    frictions, model = {}, np.zeros_like(left)
    for j in active:
        fit, _ = friction_fit(v[:, j], left[:, j], train, j)
        if fit is not None:
            frictions[j] = fit
            model[:, j] = fit.prediction
    return frictions, model


def diagnose_arm(table: RecordingTable, arm: ArmModel, heldout_from: float | None = None,
                 train_fraction: float = 0.6) -> ArmDiagnosis:
    started = time.perf_counter()
    timings: dict[str, float] = {}
    n = table.n_joints
    t = table.t - table.t[0]
    start = heldout_from if heldout_from is not None else float(t[int(train_fraction * len(t))])
    train = t < start
    if train.sum() < 10 or (~train).sum() < 10:
        raise ValueError(f"held-out split at {start:.3g} s leaves fewer than 10 rows on one side")
    v, a = accelerations(table)
    tau_nom = inverse_dynamics(arm, table.q, v, a)
    timings["inverse_dynamics_s"] = time.perf_counter() - started
    r = table.tau - tau_nom
    kinds = joint_kinds(arm)
    active = [j for j in range(n) if moved(table.q[:, j], v[:, j])]
    noise = [float(np.std(np.diff(r[:, j])) / math.sqrt(2)) for j in range(n)]
    offset = torque_time_offset(t, table.tau, tau_nom, v, train, active, noise)
    q = table.q
    if offset is not None:
        # the motion onto the torque's clock (the measured torque is never resampled)
        q, v, a = (shifted(t, x, -offset.seconds) for x in (table.q, v, a))
        tau_nom = inverse_dynamics(arm, q, v, a)
        r = table.tau - tau_nom

    findings: list[ArmFinding] = []
    not_reported: list[str] = []
    Y = regressor(arm, q, v, a)
    cols = base_columns(Y[train][:: max(1, int(train.sum()) // 400)])
    # friction and rigid-body errors share the residual: alternate (a wrong payload looks like
    # an offset to a per-joint fit, a friction left in looks like inertia to the coupled one)
    # rigid body first: a payload error is large and smooth, and a per-joint offset would
    # otherwise take the part of it that the posture barely changes
    rb, rb_text, rb_wrong = _rigid_body_fit(arm, Y, cols, r, train, active)
    frictions: dict[int, ChannelFit] = {}
    model = np.zeros_like(r)
    for _ in range(ROUNDS):
        frictions, model = _friction_fits(v, r - rb, train, active)
        rb, rb_text, rb_wrong = _rigid_body_fit(arm, Y, cols, r - model, train, active)
    worse = _made_worse(r, model, rb, train, noise, active) if rb_text is not None else []
    if worse:
        # fitted jointly with each joint's friction above and still worse somewhere: dropped
        not_reported.append(f"{rb_text[0]} (makes {', '.join(worse)} worse on the held-out rows: not accepted)")
        rb, rb_text = np.zeros_like(r), None
        frictions, model = _friction_fits(v, r, train, active)
    model_wrong = [rb_wrong] if rb_wrong is not None else []
    timings["fit_s"] = time.perf_counter() - started - sum(timings.values())

    joints = []
    for j in range(n):
        before = _rms(r[~train, j])
        after = _rms((r - model - rb)[~train, j])
        fit = frictions.get(j)
        if fit is not None:
            text, p, e = _describe_friction(fit, v[:, j], kinds[j])
            before_j = _rms((r - rb)[~train, j])
            solo = _rms((r - rb)[~train, j] - fit.prediction[~train])
            if parameter_violations(p):
                # the fit keeps friction >= 0 (a negative law is refused), so this is a guard, not a path
                model_wrong.append(f"the model is wrong here: {text} would need {'; '.join(parameter_violations(p))}")
                after = _rms((r - rb)[~train, j])
            elif uncertain(p, e):
                not_reported.append(text + " (standard error larger than half the value: not reported)")
                after = _rms((r - rb)[~train, j])
            elif solo > (1 - MIN_CONFIRMED_REDUCTION) * before_j:
                not_reported.append(text + f" (held-out RMS {before_j:.3g} -> {solo:.3g}: not confirmed, not reported)")
                after = before_j
            else:
                findings.append(ArmFinding(fit.effects, j, p, e, text, 1 - solo / max(before_j, 1e-12)))
        joints.append(JointTorque(j, j in active, before, after, noise[j], kinds[j]))
    if rb_text is not None:
        text, p, gain, effects = rb_text
        findings.append(ArmFinding(effects, None, p, {}, text, gain))
    findings.sort(key=lambda f: -f.heldout_reduction)
    # no nominal sensor to compare with: the recording's own steps and velocity shift
    sensors = sensor_findings(table.q, table.dq, table.tau, table.dt, None, None, active, kinds)
    lag = velocity_lag(t, table.q, table.dq, active)
    timings["total_s"] = time.perf_counter() - started
    return ArmDiagnosis(findings, joints, start, not_reported, timings, sensors, model_wrong, offset, lag)


def arm_summary(d: ArmDiagnosis) -> dict:
    """The JSON summary of an arm-torque diagnosis."""
    return {
        "verdict": d.verdict, "heldout_from_s": d.heldout_start, "not_reported": d.not_reported,
        "model_wrong": d.model_wrong,
        "torque_time_offset_s": d.time_offset.seconds if d.time_offset else 0.0,
        "torque_time_offset_p": d.time_offset.p_value if d.time_offset else None,
        "velocity_column_lag_s": d.velocity_lag.seconds if d.velocity_lag else 0.0,
        "sensor_findings": [{"effect": f.effect, "channel": f.channel, "joint": f.joint + 1, "parameters": f.params,
                             "text": f.text} for f in d.sensor_findings],
        "findings": [{"rank": i + 1, "effects": list(f.effects), "joint": None if f.joint is None else f.joint + 1,
                      "parameters": f.params, "stderr": f.stderr, "text": f.text,
                      "heldout_rms_reduction": f.heldout_reduction} for i, f in enumerate(d.findings)],
        "joints": [{"joint": j.joint + 1, "kind": j.kind, "unit": units_of(j.kind).effort, "moved": j.moved,
                    "heldout_rms_nominal": j.rms_nominal,
                    "heldout_rms_fitted": j.rms_fitted, "noise": j.noise} for j in d.joints],
        "timings_s": d.timings,
    }
