"""A fit as plant-file parameters (SI, with standard errors), in a test engineer's words, and
the nominal plant with the fitted effects switched on."""
from __future__ import annotations

import math

import numpy as np

from spacearm.offline.diagnosis.fitting import ChannelFit
from spacearm.offline.diagnosis.gear_effects import GEAR_EFFECTS
from spacearm.offline.diagnosis.joint_units import units_of
from spacearm.controller.recording.csv_export import WRENCH_COLUMNS
from spacearm.firmware_sim.plant import JointParams, PlantConfig

CI95 = 1.96


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
        elif effect == "gravity_load" and "load_force" in coef:
            # a slide's load: the plant's G cos(angle) along the axis, so |F| at angle 0 (pulls
            # toward -q, the servo pushes +F) or pi (pulls toward +q)
            force = float(coef["load_force"])
            p["gravity_torque"], p["gravity_angle"] = abs(force), 0.0 if force >= 0.0 else math.pi
            e["gravity_torque"] = float(err["load_force"])
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


def describe(fit: ChannelFit, p: dict[str, float], e: dict[str, float], reversals: int | None = None,
             kind: str = "revolute") -> str:
    """The finding in a test engineer's words. `reversals`: velocity sign changes of the
    joint in the recording; without any, friction laws cannot be told apart (each is a
    constant drag at constant speed) and the text says so. `kind`: the joint's (prismatic:
    N, N s/m, m)."""
    where = f"joint {fit.index + 1}" if fit.channel != "wrench" else f"F/T {WRENCH_COLUMNS[fit.index]}"
    unit = "N" if fit.index < 3 else "N m"
    u = units_of(kind)
    parts = []
    # +- is the 95 % interval (1.96 standard errors; the benchmark checks how often it holds)
    pm = lambda k: f" +- {CI95 * e[k]:.2g}" if k in e and np.isfinite(e[k]) else ""
    for effect in fit.effects:
        if effect == "coulomb":
            parts.append(f"Coulomb friction about {p['coulomb_friction']:.3g}{pm('coulomb_friction')} {u.effort}, " + (
                "a constant drag (no velocity reversal in this recording: Coulomb, Stribeck and viscous friction "
                "look alike here)" if reversals == 0 else "visible at every velocity reversal"))
        elif effect == "viscous":
            parts.append(f"viscous friction about {p['viscous_friction']:.3g}{pm('viscous_friction')} {u.damping}, "
                         "growing with speed")
        elif effect == "stribeck":
            parts.append(f"stiction (Stribeck) {p['stribeck_friction']:.3g}{pm('stribeck_friction')} {u.effort} "
                         f"above running friction, fading above about {p['stribeck_velocity']:.3g} {u.velocity}: "
                         "visible when the joint starts from rest")
        elif effect == "gravity_load" and kind == "prismatic":
            # the plant's load on a slide: G cos(angle), the same at every position
            force = p["gravity_torque"] * math.cos(p["gravity_angle"])
            parts.append(f"unmodelled load force along the axis (gravity / payload mass) about {force:.3g}"
                         f"{pm('gravity_torque')} N")
        elif effect == "gravity_load":
            parts.append(f"unmodelled load torque (gravity / payload mass) {p['gravity_torque']:.3g}"
                         f"{pm('gravity_torque')} N m, depending on position, peak at q = "
                         f"{math.degrees(-p['gravity_angle']):.0f} deg")
        elif effect == "torque_saturation":
            parts.append(f"drive {'force' if kind == 'prismatic' else 'torque'} saturates at about "
                         f"{p['torque_limit_joint']:.3g} {u.effort} (joint side) in the fastest accelerations")
        elif effect == "latency":
            n = p["feedback_latency_cycles"]
            parts.append(f"position feedback arrives {n} cycle{'s' if n > 1 else ''} late ({20 * n} ms at 50 Hz)")
        elif effect == "backlash":
            err = e.get("backlash", float("nan"))
            unc = f" +- {1e3 * CI95 * err:.1g}" if np.isfinite(err) else ""
            parts.append(f"backlash (play in the gear) about {1e3 * p['backlash']:.2g}{unc} {u.small_position}: the "
                         "drive hunts, torque ripple the nominal model lacks")
        elif effect == "elasticity":
            parts.append(f"elastic gear, stiffness about {p['joint_stiffness']:.3g}{pm('joint_stiffness')} "
                         f"{u.stiffness}: " + GEAR_SIGNS.get(fit.judged_by, GEAR_SIGNS["envelope"]))
        elif effect == "ft_bias":
            parts.append(f"constant offset {p['bias']:.3g}{pm('bias')} {unit}")
        elif effect == "ft_drift":
            parts.append(f"offset drifting by {60 * p['drift']:.3g} {unit} per minute (from {p['bias']:.3g} {unit})")
    return f"{where}: " + " and ".join(parts) + (" (+- : 95 % interval)" if e else "")


def stroke_load_text(at: tuple[float, float, float], q: np.ndarray) -> str:
    """What a load fit knows where its amplitude and angle are not pinned down (a short stroke):
    its torque at the travel's centre, `at` = (torque, standard error, centre) in N m and rad."""
    torque, err, centre = at
    return (f"; over this stroke (q = {math.degrees(float(np.min(q))):.0f} .. {math.degrees(float(np.max(q))):.0f} "
            f"deg) it is {torque:.3g} +- {CI95 * err:.2g} N m at q = {math.degrees(centre):.0f} deg, well known, while "
            "its amplitude and angle are not: the stroke is too short to tell a constant from a slow cosine")


GEAR_SIGNS = {"stiff gear": "the motor runs ahead of the link by the gear's deflection, a smooth torque term the "
                             "nominal model lacks",
              "spectrum": "the drive chatters against the resolver at other frequencies than the nominal model's "
                          "(judged by the chatter's spectrum)",
              "envelope": "the drive rings, torque ripple the nominal model lacks"}


def apply_fits(nominal: PlantConfig, fits: list[ChannelFit]) -> PlantConfig:
    """A copy of the nominal plant with the fitted effects switched on."""
    n = max([len(nominal.joints)] + [f.index + 1 for f in fits if f.channel != "wrench"])
    joints = [nominal.joint_params(i) for i in range(n)]
    bias, drift = list(nominal.ft.bias), list(nominal.ft.drift)
    for fit in fits:
        p, _ = plant_parameters(fit)
        if fit.channel == "wrench":
            bias[fit.index] += p.get("bias", 0.0)
            drift[fit.index] += p.get("drift", 0.0)
            continue
        if "gravity_torque" in p and joints[fit.index].prismatic:
            p = _on_the_slide(joints[fit.index], p)
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


def _on_the_slide(nominal: JointParams, p: dict[str, float]) -> dict[str, float]:
    """A fitted load force on a prismatic joint added to the nominal one (a known weight on a
    vertical rail stays when a payload's is found missing): only G cos(angle), the force along
    the axis, acts on a slide, so the sum is written as its size at angle 0 or pi."""
    along = nominal.gravity_torque * math.cos(nominal.gravity_angle) + \
        p["gravity_torque"] * math.cos(p["gravity_angle"])
    return p | {"gravity_torque": abs(along), "gravity_angle": 0.0 if along >= 0.0 else math.pi}
