"""A loose or elastic gear's whole SYNC period under a drive's servo law, on local variables.

JointModel steps a two-mass joint one sub-step at a time through drive_torque(), the servo
callback, _substep_two_mass() and advance_motor(), reading every parameter again each sub-step:
a coupled plant (contact world, rigid-body arm) needs that, since something acts between the
sub-steps. A joint on its own does not, and re-reading the parameters and calling back into the
drive were most of the cost of the diagnosis's gear fits (some fifty replays of one joint).
This is that arithmetic in the same order (the same bits: tests/firmware_sim/
test_two_mass_period.py), with the constants read once a period and the servo law handed in
as data, as the compiled core's rigid_period() takes it (simcore.SERVO_OFF / SERVO_CSP). The
core has a copy of it in C (_simcore.c two_mass_period), which JointModel runs where it is
built; this one is the pure-Python path and the reference the core is tested against.
"""
from __future__ import annotations

import math

from spacearm.firmware_sim.simcore import SERVO_OFF


def two_mass_period(fractions, kind: int, h: float, held: bool, external: float, q: float, qd: float,
                    theta: float, thetad: float, tau_m: float, q_start: float, q_end: float, v_ff: float,
                    torque_ff: float, constants: tuple) -> tuple:
    """One sub-step of length h per fraction s of the period; the arguments as rigid_period()'s,
    `constants` those of JointModel._core_constants() for a two-mass gear.
    -> (q, qd, theta, thetad, tau_m, q_ref, v_ref). Python's round(), cos() or sin() raise on
    a non-finite state before anything is written back, where the sub-step path would have
    written the sub-steps before it."""
    (bias, quantum, limit, gear_ratio, efficiency, amplitude, angle, constant_load, load, coulomb, viscous,
     stribeck, stribeck_velocity, inertia, te_amplitude, te_harmonic, te_phase, bandwidth_hz, damping,
     j_link, stiffness, j_motor, gear_damping, half) = constants
    # servo_torque's factors, grouped as it groups them
    w = 2.0 * math.pi * bandwidth_hz
    ww, wd = w * w, 2.0 * damping * w
    te_arg = te_harmonic * gear_ratio          # transmission_error's harmonic * gear_ratio * theta
    static = coulomb + stribeck                # effects.static_friction
    off = kind == SERVO_OFF
    q_ref = v_ref = math.nan
    for s in fractions:
        # drive_torque(): the servo on the resolver's reading and the motor's own speed (collocated)
        x = q + bias
        q_meas = x if quantum <= 0.0 else round(x / quantum) * quantum
        if off:
            q_ref, v_ref, tau_m = q_meas, 0.0, 0.0
        else:
            q_ref = q_start + s * (q_end - q_start)
            v_ref = v_ff
            tau_m = inertia * (ww * (q_ref - q_meas) + wd * (v_ref - thetad)) / gear_ratio + torque_ff
        tau_m = tau_m if tau_m < limit else limit       # min(limit, .), then max(-limit, .): the same
        tau_m = tau_m if tau_m > -limit else -limit     # picks, NaN and signed zeros alike
        if held:
            qd = thetad = 0.0
            continue
        drive = tau_m * gear_ratio * efficiency
        # advance_motor(): the gear's play (dead_zone) and transmission error couple motor and link
        out = theta + (te_amplitude * math.sin(te_arg * theta + te_phase) if te_amplitude != 0.0 else 0.0)
        deflection = out - q
        deflection = deflection - half if deflection > half else deflection + half if deflection < -half else 0.0
        coupling = stiffness * deflection + (gear_damping * (thetad - qd) if deflection != 0.0 else 0.0)
        thetad += (drive - coupling) / j_motor * h
        theta += thetad * h
        # _substep_two_mass(): the link, sticking below the break-away torque
        if not constant_load:
            load = amplitude * math.cos(q + angle)
        tau = coupling - external - load
        if abs(qd) > 1e-6 or static == 0.0:
            f = viscous * qd                    # effects.friction_torque, inline: every sub-step
            if qd != 0.0 and (coulomb > 0.0 or stribeck > 0.0):
                level = coulomb
                if stribeck > 0.0:
                    level += stribeck * math.exp(-(qd / stribeck_velocity) ** 2)
                f += math.copysign(level, qd)
            tau -= f
            qd += tau / j_link * h
        elif abs(tau) > static:
            qd += (tau - math.copysign(static, tau)) / j_link * h
        else:
            qd = 0.0
        q += qd * h
    return q, qd, theta, thetad, tau_m, q_ref, v_ref
