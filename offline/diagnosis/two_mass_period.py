"""A loose or elastic gear's SYNC period under the direct path's CSP servo, on local variables.

The plant (firmware_sim.plant.JointModel.stepper) steps a two-mass joint one sub-step at a
time through drive_torque(), the servo callback, _substep_two_mass() and advance_motor(),
reading every parameter again each sub-step; the compiled core takes only rigid gears. The
diagnosis's gear fits (backlash, elasticity) replay such joints some fifty times, and those
calls were most of their cost. This is the same arithmetic in the same order (the same bits:
tests/diagnosis/test_replay_cost.py), with the constants read once a period.
"""
from __future__ import annotations

import math


def two_mass_period(joint, drive):
    """A replacement for `joint.substeps(fractions, h)` (the joint driven by `drive`, a
    direct_sim._CspDrive); a braked or jammed joint is left to the plant's own path."""
    plant_substeps = type(joint).substeps.__get__(joint)

    def substeps(fractions, h: float) -> None:
        if joint.brake_engaged or joint.stalled:
            plant_substeps(fractions, h)
            return
        p = joint.params
        bias, quantum = p.encoder_bias, p.position_quantum
        gear_ratio, efficiency = p.gear_ratio, p.gear_efficiency
        # servo_torque's constants, in its order of operations
        w = 2.0 * math.pi * p.servo_bandwidth_hz
        ww, wd = w * w, 2.0 * p.servo_damping * w
        inertia = joint.effective_inertia
        limit = joint.max_motor_torque
        if p.torque_limit > 0.0:
            limit = min(limit, p.torque_limit)
        # advance_motor's
        j_link = max(p.link_inertia, 1e-3)
        stiffness = p.joint_stiffness or joint.RIGID_GEAR_STIFFNESS
        j_motor = p.motor_inertia * p.gear_ratio ** 2
        damping = p.joint_damping or 0.2 * math.sqrt(stiffness * j_motor * j_link / (j_motor + j_link))
        te_amplitude, te_arg = p.te_amplitude, p.te_harmonic * gear_ratio
        te_phase = p.te_phase
        half = 0.5 * p.backlash
        # _load's and the friction's
        amplitude, angle, prismatic = joint.load_amplitude, p.gravity_angle, p.prismatic
        coulomb, viscous, stribeck, stribeck_velocity = (p.coulomb_friction, p.viscous_friction,
                                                         p.stribeck_friction, p.stribeck_velocity)
        static = coulomb + stribeck
        external = joint.external_torque
        q_start, q_end, v_ff = drive.q_start, drive.q_end, drive.v_ff
        q, qd, theta, thetad = joint.q, joint.qd, joint.theta, joint.thetad
        tau_m = joint.motor_torque
        q_ref = drive.q_ref
        for s in fractions:
            # drive_torque(): the servo on the resolver's reading and the motor's speed, saturated
            x = q + bias
            q_meas = x if quantum <= 0.0 else round(x / quantum) * quantum
            q_ref = q_start + s * (q_end - q_start)
            tau_m = inertia * (ww * (q_ref - q_meas) + wd * (v_ff - thetad)) / gear_ratio
            tau_m = tau_m if tau_m < limit else limit       # min(limit, .), then max(-limit, .)
            tau_m = tau_m if tau_m > -limit else -limit
            drive_torque = tau_m * gear_ratio * efficiency
            # advance_motor()
            out = theta + (te_amplitude * math.sin(te_arg * theta + te_phase) if te_amplitude != 0.0 else 0.0)
            deflection = out - q
            deflection = deflection - half if deflection > half else deflection + half if deflection < -half else 0.0
            coupling = stiffness * deflection + (damping * (thetad - qd) if deflection != 0.0 else 0.0)
            thetad += (drive_torque - coupling) / j_motor * h
            theta += thetad * h
            # _substep_two_mass(): the link
            load = 0.0 if amplitude == 0.0 else amplitude * math.cos(angle) if prismatic else \
                amplitude * math.cos(q + angle)
            tau = coupling - external - load
            if abs(qd) > 1e-6 or static == 0.0:
                f = viscous * qd
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
        joint.q, joint.qd, joint.theta, joint.thetad, joint.motor_torque = q, qd, theta, thetad, tau_m
        drive.q_ref = q_ref

    return substeps
