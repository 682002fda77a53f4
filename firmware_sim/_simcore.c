/* Compiled core of the simulator's SYNC hot path (issue 35): a drive's SYNC begin that changes no state
 * (its RPDO objects read straight from the data store), a joint's whole SYNC period of sub-steps
 * with its drive's servo law (a rigid gear, or a loose or elastic one: firmware_sim/two_mass.py),
 * and the drive's actual values as integers; and the
 * frames: a burst's RPDOs stored (rpdo_burst) and a SYNC's TPDOs sampled into its burst
 * (tpdo_burst), for the nodes whose frames the Python path would handle plainly, each checked
 * per frame or SYNC and any other handed back to Python (runner.Simulator).
 *
 * Bit for bit the pure-Python path (firmware_sim/plant.py JointModel.stepper, two_mass.py,
 * joint_drive.JointDriveNode._servo / servo_torque / _update_od): the same IEEE double
 * operations in the same order, built with -ffp-contract=off (no fused multiply-add), the
 * same libm calls Python's math module makes (cos, sin, exp, pow), and Python's round()
 * (half to even, nearbyint in the default rounding mode). Anything the Python path would
 * raise on (round() of NaN or infinity) is handed back to Python, which raises it.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

/* servo kinds the Python side selects (joint_drive.JointDriveNode.period_servo) */
enum { SERVO_OFF = 0, SERVO_CSP = 1 };

static double py_round(double x) {
    /* round() of a float in CPython: half away from zero, then back to even on a tie; an int,
     * so a zero has no sign (round(-0.3) * quantum is +0.0 in Python, -0.0 from C's round) */
    double r = round(x);
    if (fabs(x - r) == 0.5)
        r = 2.0 * round(x / 2.0);
    return r == 0.0 ? 0.0 : r;
}

static double friction_torque(double v, double coulomb, double viscous, double stribeck, double stribeck_velocity) {
    double f = viscous * v;
    if (v != 0.0 && (coulomb > 0.0 || stribeck > 0.0)) {
        double level = coulomb;
        if (stribeck > 0.0) {
            /* Python's x ** 2 on a float is pow(|x|, 2) (float_pow negates odd powers only) */
            double r = v / stribeck_velocity;
            level += stribeck * exp(-pow(fabs(r), 2.0));
        }
        f += copysign(level, v);
    }
    return f;
}

#define N_DYNAMIC 13
#define N_CONSTANTS 19

/* rigid_period(fractions, kind, h, held, external, q, qd, theta, thetad, tau_m, q_start, q_end, v_ff,
 *              torque_ff, constants)
 * constants (plant.JointModel._core_constants, fixed while the joint's parameters, torque limit
 * and load stand): (bias, quantum, limit, gear_ratio, efficiency, amplitude, angle,
 * constant_load, load, coulomb, viscous, stribeck, stribeck_velocity, inertia, te_amplitude,
 * te_harmonic, te_phase, servo bandwidth Hz, servo damping)
 * -> (q, qd, theta, thetad, tau_m, q_ref, v_ref), or None when Python's round() or cos() would
 * raise on a value (a non-finite position): the caller reruns the period in Python.
 * fractions: a list or tuple of floats (the servo's interpolation points). */
/* The encoder's reading of x: round(x / quantum) * quantum, x itself without a quantum; 0 where
 * x / quantum is not finite (Python's round() raises: the caller's path). */
static int measured(double x, double quantum, double *out) {
    if (quantum <= 0.0) {
        *out = x;
        return 1;
    }
    double r = x / quantum;
    if (!isfinite(r))
        return 0;
    *out = py_round(r) * quantum;
    return 1;
}

#define N_CONSTANTS_TWO_MASS 24

/* A period's arguments by name (rigid_period's and two_mass_period's): the joint's state, its
 * drive's servo law, the constants (plant.JointModel._core_constants) and the fractions. */
struct period {
    long kind;
    int held, constant_load;
    double h, external, q, qd, theta, thetad, tau_m, q_start, q_end, v_ff, torque_ff;
    double bias, quantum, limit, gear_ratio, efficiency, amplitude, angle, load, coulomb, viscous, stribeck,
        stribeck_velocity, inertia, te_amplitude, te_harmonic, te_phase, bandwidth_hz, damping;
    double j_link, stiffness, j_motor, gear_damping, half;      /* a two-mass gear's only */
    PyObject *fractions;                                          /* a fast sequence, a new reference */
};

/* 0 with the error set, or the period with n_constants constants read into p. */
static int period_args(const char *name, PyObject *const *args, Py_ssize_t nargs, int n_constants,
                       struct period *p) {
    if (nargs != N_DYNAMIC + 2) {
        PyErr_Format(PyExc_TypeError, "%s takes %d arguments (%zd given)", name, N_DYNAMIC + 2, nargs);
        return 0;
    }
    PyObject *constants = args[nargs - 1];
    if (!PyTuple_Check(constants) || PyTuple_GET_SIZE(constants) != n_constants) {
        PyErr_Format(PyExc_TypeError, "%s: %d constants", name, n_constants);
        return 0;
    }
    double a[N_DYNAMIC - 1], c[N_CONSTANTS_TWO_MASS];
    p->kind = PyLong_AsLong(args[1]);
    for (int i = 0; i < N_DYNAMIC - 1; i++)
        a[i] = PyFloat_AsDouble(args[i + 2]);
    for (int i = 0; i < n_constants; i++)
        c[i] = PyFloat_AsDouble(PyTuple_GET_ITEM(constants, i));
    if (PyErr_Occurred())
        return 0;
    if (p->kind != SERVO_OFF && p->kind != SERVO_CSP) {
        PyErr_SetString(PyExc_ValueError, "unknown servo kind");
        return 0;
    }
    p->h = a[0], p->held = a[1] != 0.0, p->external = a[2];
    p->q = a[3], p->qd = a[4], p->theta = a[5], p->thetad = a[6], p->tau_m = a[7];
    p->q_start = a[8], p->q_end = a[9], p->v_ff = a[10], p->torque_ff = a[11];
    p->bias = c[0], p->quantum = c[1], p->limit = c[2], p->gear_ratio = c[3], p->efficiency = c[4];
    p->amplitude = c[5], p->angle = c[6], p->constant_load = c[7] != 0.0, p->load = c[8];
    p->coulomb = c[9], p->viscous = c[10], p->stribeck = c[11], p->stribeck_velocity = c[12];
    p->inertia = c[13], p->te_amplitude = c[14], p->te_harmonic = c[15], p->te_phase = c[16];
    p->bandwidth_hz = c[17], p->damping = c[18];
    if (n_constants == N_CONSTANTS_TWO_MASS)
        p->j_link = c[19], p->stiffness = c[20], p->j_motor = c[21], p->gear_damping = c[22], p->half = c[23];
    p->fractions = PySequence_Fast(args[0], "fractions must be a sequence");
    return p->fractions != NULL;
}

/* The drive's servo (JointDriveNode._servo + servo_torque) at s of the period, on the encoder's
 * reading q_meas and the speed fed back: the motor torque, saturated as min(limit, .) then
 * max(-limit, .) pick (NaN and signed zeros alike); the reference into q_ref and v_ref. */
static double servo(const struct period *p, double s, double q_meas, double speed, double *q_ref, double *v_ref) {
    double tau_m;
    if (p->kind == SERVO_OFF) {
        *q_ref = q_meas;
        *v_ref = 0.0;
        tau_m = 0.0;
    } else {
        const double w = 2.0 * M_PI * p->bandwidth_hz;      /* servo_torque's, in its order */
        *q_ref = p->q_start + s * (p->q_end - p->q_start);
        *v_ref = p->v_ff;
        double tau_joint = p->inertia * (w * w * (*q_ref - q_meas) + 2.0 * p->damping * w * (*v_ref - speed));
        tau_m = tau_joint / p->gear_ratio + p->torque_ff;
    }
    tau_m = tau_m < p->limit ? tau_m : p->limit;
    return tau_m > -p->limit ? tau_m : -p->limit;
}

static PyObject *rigid_period(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    (void)self;
    struct period p;
    if (!period_args("rigid_period", args, nargs, N_CONSTANTS, &p))
        return NULL;
    PyObject *fractions = p.fractions;
    const double h = p.h, external = p.external, bias = p.bias, quantum = p.quantum;
    const int held = p.held;
    double q = p.q, qd = p.qd, theta = p.theta, thetad = p.thetad, tau_m = p.tau_m, load = p.load;
    if (!p.constant_load && isinf(q + p.angle))
        goto python;                /* stepper()'s first load, math.cos(q + angle), raises */
    const double static_ = p.coulomb + p.stribeck;       /* effects.static_friction */
    double q_ref = NAN, v_ref = NAN;

    Py_ssize_t n = PySequence_Fast_GET_SIZE(fractions);
    PyObject **items = PySequence_Fast_ITEMS(fractions);
    if (n == 0)
        goto python;
    double held_measured = 0.0;
    if (held && !measured(q + bias, quantum, &held_measured))
        goto python;
    for (Py_ssize_t i = 0; i < n; i++) {
        double s = PyFloat_AsDouble(items[i]);
        if (s == -1.0 && PyErr_Occurred()) {
            Py_DECREF(fractions);
            return NULL;
        }
        double q_meas = held_measured;
        if (!held && !measured(q + bias, quantum, &q_meas))
            goto python;
        tau_m = servo(&p, s, q_meas, qd, &q_ref, &v_ref);
        if (held) {
            qd = thetad = 0.0;
            continue;
        }
        double drive = tau_m * p.gear_ratio * p.efficiency;
        if (!p.constant_load) {
            if (!isfinite(q + p.angle))
                goto python;                     /* math.cos raises on an infinity */
            load = p.amplitude * cos(q + p.angle);
        }
        double tau = drive - external - load;
        double v = thetad;
        if (fabs(v) > 1e-6 || static_ == 0.0) {
            tau -= friction_torque(v, p.coulomb, p.viscous, p.stribeck, p.stribeck_velocity);
        } else if (fabs(tau) <= static_) {
            tau = 0.0;
            thetad = 0.0;
        } else {
            tau -= copysign(static_, tau);
        }
        thetad += tau / p.inertia * h;
        theta += thetad * h;
        if (p.te_amplitude > 0.0) {
            /* transmission_error and its slope (effects/transmission.py); math.sin raises on an infinity */
            double wt = p.te_harmonic * p.gear_ratio;
            double phase = wt * theta + p.te_phase;
            if (!isfinite(phase))
                goto python;
            q = theta + p.te_amplitude * sin(phase);
            qd = thetad * (1.0 + p.te_amplitude * wt * cos(phase));
        } else {
            q = theta;
            qd = thetad;
        }
    }
    Py_DECREF(fractions);
    return Py_BuildValue("(ddddddd)", q, qd, theta, thetad, tau_m, q_ref, v_ref);
python:
    Py_DECREF(fractions);
    Py_RETURN_NONE;
}

/* two_mass_period(fractions, kind, h, held, external, q, qd, theta, thetad, tau_m, q_start, q_end,
 *                 v_ff, torque_ff, constants)
 * firmware_sim/two_mass.py's two_mass_period, a loose or elastic gear's period: the arguments and
 * answer as rigid_period's; the constants those of a two-mass JointModel._core_constants():
 * rigid_period's, then j_link, stiffness, j_motor, gear damping, half the play. None where
 * Python's round(), cos() or sin() might raise: the caller reruns the period in Python. */
static PyObject *two_mass_period(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    (void)self;
    struct period p;
    if (!period_args("two_mass_period", args, nargs, N_CONSTANTS_TWO_MASS, &p))
        return NULL;
    PyObject *fractions = p.fractions;
    const double h = p.h, external = p.external, half = p.half;
    double q = p.q, qd = p.qd, theta = p.theta, thetad = p.thetad, tau_m = p.tau_m, load = p.load;
    const double te_arg = p.te_harmonic * p.gear_ratio;
    const double static_ = p.coulomb + p.stribeck;
    double q_ref = NAN, v_ref = NAN;

    Py_ssize_t n = PySequence_Fast_GET_SIZE(fractions);
    PyObject **items = PySequence_Fast_ITEMS(fractions);
    if (n == 0)
        goto python;
    for (Py_ssize_t i = 0; i < n; i++) {
        double s = PyFloat_AsDouble(items[i]);
        if (s == -1.0 && PyErr_Occurred()) {
            Py_DECREF(fractions);
            return NULL;
        }
        double q_meas;
        if (!measured(q + p.bias, p.quantum, &q_meas))
            goto python;
        /* drive_torque(): the servo on the motor's own speed (collocated) */
        tau_m = servo(&p, s, q_meas, thetad, &q_ref, &v_ref);
        if (p.held) {
            qd = thetad = 0.0;
            continue;
        }
        double drive = tau_m * p.gear_ratio * p.efficiency;
        /* advance_motor() */
        double te = 0.0;
        if (p.te_amplitude != 0.0) {
            double phase = te_arg * theta + p.te_phase;
            if (!isfinite(phase))
                goto python;                     /* math.sin raises on an infinity */
            te = p.te_amplitude * sin(phase);
        }
        double deflection = theta + te - q;
        deflection = deflection > half ? deflection - half : deflection < -half ? deflection + half : 0.0;
        double coupling = p.stiffness * deflection + (deflection != 0.0 ? p.gear_damping * (thetad - qd) : 0.0);
        thetad += (drive - coupling) / p.j_motor * h;
        theta += thetad * h;
        /* _substep_two_mass(): the link */
        if (!p.constant_load) {
            if (!isfinite(q + p.angle))
                goto python;                     /* math.cos raises on an infinity */
            load = p.amplitude * cos(q + p.angle);
        }
        double tau = coupling - external - load;
        if (fabs(qd) > 1e-6 || static_ == 0.0) {
            tau -= friction_torque(qd, p.coulomb, p.viscous, p.stribeck, p.stribeck_velocity);
            qd += tau / p.j_link * h;
        } else if (fabs(tau) > static_) {
            qd += (tau - copysign(static_, tau)) / p.j_link * h;
        } else {
            qd = 0.0;
        }
        q += qd * h;
    }
    Py_DECREF(fractions);
    return Py_BuildValue("(ddddddd)", q, qd, theta, thetad, tau_m, q_ref, v_ref);
python:
    Py_DECREF(fractions);
    Py_RETURN_NONE;
}

static int clamp_round(double x, double lo, double hi, long long *out) {
    /* max(lo, min(hi, round(x))): 0 when x is not finite (Python's round() raises: the caller's
     * path); _i32's bounds for the 32-bit objects, the 16-bit ones' for torque and temperature */
    if (!isfinite(x))
        return 0;
    double r = py_round(x);
    if (r > hi)
        r = hi;
    if (r < lo)
        r = lo;
    *out = (long long)r;
    return 1;
}

#define I32_MIN -2147483648.0
#define I32_MAX 2147483647.0

/* The drive's actual values as its objects count them (JointDriveNode._update_od): position,
 * demand, velocity, torque (per mille of rated), following error, temperature (0.1 degC);
 * 0 when one is not finite. */
static int actual_counts(double k, double rated, double q_reported, double q_ref, double qd_reported,
                         double torque_reported, double q_measured, double temperature, long long v[6]) {
    return clamp_round(q_reported * k, I32_MIN, I32_MAX, &v[0]) && clamp_round(q_ref * k, I32_MIN, I32_MAX, &v[1]) &&
           clamp_round(qd_reported * k, I32_MIN, I32_MAX, &v[2]) &&
           clamp_round(torque_reported / rated * 1000.0, -32768.0, 32767.0, &v[3]) &&
           clamp_round((q_ref - q_measured) * k, I32_MIN, I32_MAX, &v[4]) &&
           clamp_round(temperature * 10.0, -32768.0, 32767.0, &v[5]);
}

/* actual_values(k, rated, q_reported, q_ref, qd_reported, torque_reported, q_measured, temperature)
 * -> (position, demand, velocity, torque, following error, temperature) as the drive's objects
 * count them (JointDriveNode._update_od), or None when a value is not finite. */
static PyObject *actual_values(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    (void)self;
    if (nargs != 8) {
        PyErr_Format(PyExc_TypeError, "actual_values takes 8 arguments (%zd given)", nargs);
        return NULL;
    }
    double a[8];
    for (int i = 0; i < 8; i++)
        a[i] = PyFloat_AsDouble(args[i]);
    if (PyErr_Occurred())
        return NULL;
    const double k = a[0], rated = a[1];
    long long v[6];
    if (!actual_counts(k, rated, a[2], a[3], a[4], a[5], a[6], a[7], v))
        Py_RETURN_NONE;
    return Py_BuildValue("(LLLLLL)", v[0], v[1], v[2], v[3], v[4], v[5]);
}

/* One stored object's value: store[index][sub] as the little-endian integer of `size` bytes
 * (signed or not) the object's type says. 0: not stored, or stored with another length (the
 * Python path decodes what SimNode.get() would). */
static int stored_int(PyObject *store, PyObject *spec, long long *out) {
    if (!PyTuple_Check(spec) || PyTuple_GET_SIZE(spec) != 4)
        return 0;
    PyObject *entry = PyDict_GetItemWithError(store, PyTuple_GET_ITEM(spec, 0));
    if (entry == NULL || !PyDict_Check(entry))
        return 0;
    PyObject *data = PyDict_GetItemWithError(entry, PyTuple_GET_ITEM(spec, 1));
    if (data == NULL || !PyBytes_Check(data))
        return 0;
    long size = PyLong_AsLong(PyTuple_GET_ITEM(spec, 2));
    int is_signed = PyObject_IsTrue(PyTuple_GET_ITEM(spec, 3));
    if (size < 1 || size > 4 || is_signed < 0 || PyBytes_GET_SIZE(data) != size)
        return 0;
    const unsigned char *b = (const unsigned char *)PyBytes_AS_STRING(data);
    unsigned long long u = 0;
    for (long i = 0; i < size; i++)          /* exactly `size` bytes: the length was checked */
        u |= (unsigned long long)b[i] << (8 * i);
    long long v = (long long)u;
    if (is_signed && (u >> (8 * size - 1)) & 1)
        v -= 1LL << (8 * size);
    *out = v;
    return 1;
}

#define CW_FAULT_RESET 0x0080
#define CW_NEW_SETPOINT 0x0010
#define CW_HALT 0x0100
#define MODE_PROFILE_POSITION 1
#define MODE_CSP 8

/* decode_controlword's command, as the bit of a stay mask: disable voltage, quick stop,
 * shutdown, switch on, enable operation */
static int command_of(long long cw) {
    if (!(cw & 0x02))
        return 0;
    if (!(cw & 0x04))
        return 1;
    if (!(cw & 0x01))
        return 2;
    if (!(cw & 0x08))
        return 3;
    return 4;
}

/* steady_begin(store, objects, q_ref, dt, k, lo, hi, vmax, rated, enabled, fault, mode, stay_mask, halt)
 * JointDriveNode.on_sync_begin for a SYNC that changes no state: no fault reset bit, a command
 * that leaves the drive's state where it is (stay_mask: bit c for command c, from next_state;
 * `fault`: the drive is in FAULT, where only a reset acts), no mode change, no halt starting;
 * in OPERATION ENABLED only CSP (`mode` is the drive's mode, `enabled` its state).
 * store: the node's data store ({index: {sub: bytes}}); objects: (index, sub, size, signed) of
 * the controlword, modes of operation, torque offset, target position and velocity offset;
 * lo, hi, vmax: the software limits' and the maximum profile velocity's counts (enabled only).
 * -> (controlword, halt, torque_ff, limit_active, q_end, v_ff) (the last two None unless
 * enabled), or None for any other SYNC: the Python path runs it. */
static PyObject *steady_begin(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    (void)self;
    if (nargs != 14) {
        PyErr_Format(PyExc_TypeError, "steady_begin takes 14 arguments (%zd given)", nargs);
        return NULL;
    }
    PyObject *store = args[0], *objects = args[1];
    if (!PyDict_Check(store) || !PyTuple_Check(objects) || PyTuple_GET_SIZE(objects) != 5) {
        PyErr_SetString(PyExc_TypeError, "steady_begin: a dict and five object specs");
        return NULL;
    }
    double a[7];
    for (int i = 0; i < 7; i++)
        a[i] = PyFloat_AsDouble(args[i + 2]);
    int enabled = PyObject_IsTrue(args[9]), fault = PyObject_IsTrue(args[10]);
    long own_mode = PyLong_AsLong(args[11]), stay_mask = PyLong_AsLong(args[12]);
    int prev_halt = PyObject_IsTrue(args[13]);
    if (PyErr_Occurred())
        return NULL;
    const double q_start = a[0], dt = a[1], k = a[2], lo_count = a[3], hi_count = a[4], vmax_count = a[5],
                 rated = a[6];
    long long cw, mode, torque_offset, target_count, velocity_offset;
    if (!stored_int(store, PyTuple_GET_ITEM(objects, 0), &cw) ||
        !stored_int(store, PyTuple_GET_ITEM(objects, 1), &mode) ||
        !stored_int(store, PyTuple_GET_ITEM(objects, 2), &torque_offset) ||
        !stored_int(store, PyTuple_GET_ITEM(objects, 3), &target_count) ||
        !stored_int(store, PyTuple_GET_ITEM(objects, 4), &velocity_offset)) {
        if (PyErr_Occurred())
            return NULL;
        Py_RETURN_NONE;
    }
    if (cw & CW_FAULT_RESET)
        Py_RETURN_NONE;
    if (!fault && !((stay_mask >> command_of(cw)) & 1))
        Py_RETURN_NONE;
    if ((mode == MODE_CSP || mode == MODE_PROFILE_POSITION) && mode != own_mode)
        Py_RETURN_NONE;
    if (enabled && own_mode != MODE_CSP)
        Py_RETURN_NONE;
    int halt = (cw & CW_HALT) && enabled && own_mode == MODE_CSP;
    if (halt && !prev_halt)
        Py_RETURN_NONE;
    /* on_sync_begin, its operations in its order */
    double torque_ff = (double)torque_offset / 1000.0 * rated;
    if (!enabled)
        return Py_BuildValue("(LOdOOO)", cw, halt ? Py_True : Py_False, torque_ff, Py_False, Py_None, Py_None);
    if (k == 0.0 || dt == 0.0)
        Py_RETURN_NONE;           /* Python divides by zero and raises */
    double lo = lo_count / k, hi = hi_count / k, vmax = vmax_count / k;
    double target = (double)target_count / k;
    double m = target > lo ? target : lo;           /* max(lo, target) */
    double clamped = m < hi ? m : hi;               /* min(hi, .) */
    double step = clamped - q_start;
    if (fabs(step) > vmax * dt)
        step = copysign(vmax * dt, step);
    int limit_active = clamped != target || q_start + step != clamped;
    double q_end = q_start + step;
    double v_ff = step / dt + (double)velocity_offset / k;
    return Py_BuildValue("(LOdOdd)", cw, halt ? Py_True : Py_False, torque_ff, limit_active ? Py_True : Py_False,
                         q_end, v_ff);
}

/* cyclic_write's loop over values[start:n]: the index it stopped at (n: done), or -1 with an
 * exception set. The caller checked the containers' types and sizes. */
static Py_ssize_t cyclic_store(PyObject *specs, PyObject **items, Py_ssize_t n, PyObject *entries,
                               PyObject *last_values, PyObject *last_stored, PyObject *params, Py_ssize_t start) {
    Py_ssize_t i = start;
    for (; i < n; i++) {
        PyObject *value = items[i], *spec = PyTuple_GET_ITEM(specs, i), *entry = PyList_GET_ITEM(entries, i);
        if (!PyLong_CheckExact(value) || !PyTuple_Check(spec) || PyTuple_GET_SIZE(spec) != 4 || !PyDict_Check(entry))
            break;
        PyObject *sub = PyTuple_GET_ITEM(spec, 0), *key = PyTuple_GET_ITEM(spec, 3);
        int same = PyObject_RichCompareBool(value, PyList_GET_ITEM(last_values, i), Py_EQ);
        if (same < 0)
            return -1;
        if (same) {
            PyObject *stored = PyDict_GetItemWithError(entry, sub);
            if (stored == NULL && PyErr_Occurred())
                return -1;
            if ((stored == NULL ? Py_None : stored) == PyList_GET_ITEM(last_stored, i))
                continue;
        }
        long size = PyLong_AsLong(PyTuple_GET_ITEM(spec, 1));
        int is_signed = PyObject_IsTrue(PyTuple_GET_ITEM(spec, 2));
        if (size < 1 || size > 4 || is_signed < 0) {
            PyErr_Clear();
            break;
        }
        int overflow = 0;
        long long v = PyLong_AsLongLongAndOverflow(value, &overflow);
        if (overflow || (v == -1 && PyErr_Occurred())) {
            PyErr_Clear();
            break;                               /* does not fit: the Python loop raises */
        }
        long long lo = is_signed ? -(1LL << (8 * size - 1)) : 0;
        long long hi = is_signed ? (1LL << (8 * size - 1)) - 1 : (1LL << (8 * size)) - 1;
        if (v < lo || v > hi)
            break;
        unsigned char buf[4];
        unsigned long long u = (unsigned long long)v;
        for (long b = 0; b < size; b++)
            buf[b] = (unsigned char)(u >> (8 * b));
        PyObject *data = PyBytes_FromStringAndSize((const char *)buf, size);
        if (data == NULL)
            return -1;
        if (PyDict_SetItem(entry, sub, data) < 0) {
            Py_DECREF(data);
            return -1;
        }
        if (PyDict_GET_SIZE(params) > 0) {
            int cached = PyDict_Contains(params, key);
            if (cached < 0 || (cached && PyObject_DelItem(params, key) < 0)) {
                Py_DECREF(data);
                return -1;
            }
        }
        Py_INCREF(value);
        PyList_SetItem(last_values, i, value);    /* steals the references */
        PyList_SetItem(last_stored, i, data);
    }
    return i;
}

/* 1: cyclic_write's containers fit n values */
static int cyclic_layout_ok(PyObject *specs, Py_ssize_t n, PyObject *entries, PyObject *last_values,
                            PyObject *last_stored, PyObject *params) {
    return PyTuple_Check(specs) && PyList_Check(entries) && PyList_Check(last_values) && PyList_Check(last_stored) &&
           PyDict_Check(params) && PyTuple_GET_SIZE(specs) >= n && PyList_GET_SIZE(entries) >= n &&
           PyList_GET_SIZE(last_values) >= n && PyList_GET_SIZE(last_stored) >= n;
}

/* cyclic_write(specs, values, entries, last_values, last_stored, params, start) -> stop
 * CyclicObjects.write's loop from object `start`: per object (specs: (sub, size, signed, key)),
 * skipped while its value equals the last one written and its stored bytes are still those;
 * else packed little-endian into entries[i][sub], its param() cache entry dropped (del, so the
 * cache's epoch moves) and remembered. Stops at the first value that is not an exact int or
 * does not fit, returning its position for the Python loop (which names the object in its
 * error); returns len(values) when done. */
static PyObject *cyclic_write(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    (void)self;
    if (nargs != 7) {
        PyErr_Format(PyExc_TypeError, "cyclic_write takes 7 arguments (%zd given)", nargs);
        return NULL;
    }
    Py_ssize_t start = PyLong_AsSsize_t(args[6]);
    if (start == -1 && PyErr_Occurred())
        return NULL;
    PyObject *values = PySequence_Fast(args[1], "values must be a sequence");
    if (values == NULL)
        return NULL;
    Py_ssize_t n = PySequence_Fast_GET_SIZE(values);
    if (!cyclic_layout_ok(args[0], n, args[2], args[3], args[4], args[5]) || start < 0) {
        Py_DECREF(values);
        PyErr_SetString(PyExc_TypeError, "cyclic_write: layout, entries and last values do not match");
        return NULL;
    }
    Py_ssize_t i = cyclic_store(args[0], PySequence_Fast_ITEMS(values), n, args[2], args[3], args[4], args[5], start);
    Py_DECREF(values);
    return i < 0 ? NULL : PyLong_FromSsize_t(i);
}

/* rpdo_store(codec, data, store, params, on_write, write_rules, aborted, stats) -> None
 * PdoEngine.on_rpdo's loop over the mapped objects, for a node whose only write callback is its
 * own write rules: per entry (index, sub, start, end, obj, size_ok, key, reacts) the slice
 * data[start:end] (Python's slicing: a short frame gives a short slice, never a read past its
 * end), counted as malformed if its size is not the object's; write_rules(index, sub, obj, chunk)
 * for the communication area, on_write(index, sub, chunk) for application objects the device
 * reacts to (`reacts`: SimNode.WRITE_REACTIONS; the others have no reaction to call); an `aborted`
 * exception (SdoAbortedError) counts as malformed and the object is not stored; else stored
 * in store[index][sub] and its param() cache entry dropped. */
static int count_malformed(PyObject *stats) {
    PyObject *n = PyObject_GetAttrString(stats, "malformed");
    if (n == NULL)
        return -1;
    PyObject *one = PyLong_FromLong(1);
    PyObject *m = one ? PyNumber_Add(n, one) : NULL;
    Py_DECREF(n);
    Py_XDECREF(one);
    if (m == NULL)
        return -1;
    int rc = PyObject_SetAttrString(stats, "malformed", m);
    Py_DECREF(m);
    return rc;
}

/* rpdo_store's loop: 0, or -1 with an exception set */
/* accepted (NULL: none): {key: chunk} of the application objects whose on_write is a pure check
 * (the same chunk always passes: JointDriveNode.PURE_WRITE_CHECK) that it let pass; a chunk
 * equal to the one it passed skips the call (issue 35: six calls a cycle for a mode of
 * operation that does not change). */
static int store_rpdo(PyObject *codec, PyObject *data, PyObject *store, PyObject *params, PyObject *on_write,
                      PyObject *write_rules, PyObject *aborted, PyObject *stats, PyObject *accepted) {
    if (!PyTuple_Check(codec) || !PyDict_Check(store) || !PyDict_Check(params)) {
        PyErr_SetString(PyExc_TypeError, "rpdo_store: a codec tuple, a store dict and a cache dict");
        return -1;
    }
    for (Py_ssize_t i = 0; i < PyTuple_GET_SIZE(codec); i++) {
        PyObject *e = PyTuple_GET_ITEM(codec, i);
        if (!PyTuple_Check(e) || PyTuple_GET_SIZE(e) != 8) {
            PyErr_SetString(PyExc_TypeError, "rpdo_store: codec entries are 8-tuples");
            return -1;
        }
        PyObject *index = PyTuple_GET_ITEM(e, 0), *sub = PyTuple_GET_ITEM(e, 1), *obj = PyTuple_GET_ITEM(e, 4),
                 *key = PyTuple_GET_ITEM(e, 6);
        Py_ssize_t start = PyLong_AsSsize_t(PyTuple_GET_ITEM(e, 2)), end = PyLong_AsSsize_t(PyTuple_GET_ITEM(e, 3));
        long index_value = PyLong_AsLong(index);
        if (PyErr_Occurred())
            return -1;
        PyObject *chunk = PySequence_GetSlice(data, start, end);
        if (chunk == NULL)
            return -1;
        int size_ok = PyObject_IsTrue(PyTuple_GET_ITEM(e, 5));
        if (size_ok <= 0) {
            Py_DECREF(chunk);
            if (size_ok < 0 || count_malformed(stats) < 0)
                return -1;
            continue;
        }
        int reacts = index_value < 0x2000 ? 1 : PyObject_IsTrue(PyTuple_GET_ITEM(e, 7));
        if (reacts < 0) {
            Py_DECREF(chunk);
            return -1;
        }
        int passed = 0;                          /* on_write let this very chunk pass before */
        if (index_value >= 0x2000 && reacts && accepted != NULL) {
            PyObject *known = PyDict_GetItemWithError(accepted, key);
            if (known == NULL && PyErr_Occurred()) {
                Py_DECREF(chunk);
                return -1;
            }
            passed = known != NULL && PyBytes_CheckExact(known) && PyBytes_CheckExact(chunk) &&
                     PyBytes_GET_SIZE(known) == PyBytes_GET_SIZE(chunk) &&
                     memcmp(PyBytes_AS_STRING(known), PyBytes_AS_STRING(chunk), PyBytes_GET_SIZE(chunk)) == 0;
        }
        PyObject *result = index_value < 0x2000
            ? PyObject_CallFunctionObjArgs(write_rules, index, sub, obj, chunk, NULL)
            : reacts && !passed ? PyObject_CallFunctionObjArgs(on_write, index, sub, chunk, NULL) : Py_NewRef(Py_None);
        if (result == NULL) {
            if (!PyErr_ExceptionMatches(aborted)) {
                Py_DECREF(chunk);
                return -1;
            }
            PyErr_Clear();
            Py_DECREF(chunk);
            if (count_malformed(stats) < 0)
                return -1;
            continue;
        }
        Py_DECREF(result);
        if (index_value >= 0x2000 && reacts && accepted != NULL && !passed && PyBytes_CheckExact(chunk) &&
            PyDict_SetItem(accepted, key, chunk) < 0) {
            Py_DECREF(chunk);
            return -1;
        }
        PyObject *entry = PyDict_GetItemWithError(store, index);
        if (entry == NULL) {
            if (PyErr_Occurred() || (entry = PyDict_New()) == NULL) {
                Py_DECREF(chunk);
                return -1;
            }
            int rc = PyDict_SetItem(store, index, entry);
            Py_DECREF(entry);                      /* the store holds it */
            if (rc < 0) {
                Py_DECREF(chunk);
                return -1;
            }
        }
        int rc = PyObject_SetItem(entry, sub, chunk);
        Py_DECREF(chunk);
        if (rc < 0)
            return -1;
        if (PyDict_GET_SIZE(params) > 0) {
            int cached = PyDict_Contains(params, key);
            if (cached < 0 || (cached && PyObject_DelItem(params, key) < 0))
                return -1;
        }
    }
    return 0;
}

static PyObject *rpdo_store(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    (void)self;
    if (nargs != 8) {
        PyErr_Format(PyExc_TypeError, "rpdo_store takes 8 arguments (%zd given)", nargs);
        return NULL;
    }
    if (store_rpdo(args[0], args[1], args[2], args[3], args[4], args[5], args[6], args[7], NULL) < 0)
        return NULL;
    Py_RETURN_NONE;
}

/* Interned attribute names rpdo_burst reads (module init) */
static PyObject *s_powered, *s_silent, *s_faults, *s_stats, *s_nmt_state, *s_rpdos, *s_codec, *s_rx_frames, *s_in_rpdo,
    *s_on_write, *s_on_rpdo, *s_send_tpdos, *s_ignore_sync, *s_drop_tx, *s_corrupt_tx, *s_plain_cobs,
    *s_read_callbacks, *s_send, *s_send_many_name, *s_tpdos, *s_core_key, *s_store_generation, *s_core_rows,
    *s_sync_counter, *s_syncs, *s_tx_frames, *one_;

/* obj.name += 1 */
static int count_up(PyObject *obj, PyObject *name) {
    PyObject *n = PyObject_GetAttr(obj, name);
    if (n == NULL)
        return -1;
    PyObject *m = PyNumber_Add(n, one_);
    Py_DECREF(n);
    if (m == NULL)
        return -1;
    int rc = PyObject_SetAttr(obj, name, m);
    Py_DECREF(m);
    return rc;
}

/* 1: obj.name is true, 0: false, -1: an exception */
static int attr_true(PyObject *obj, PyObject *name) {
    PyObject *v = PyObject_GetAttr(obj, name);
    if (v == NULL)
        return -1;
    int t = PyObject_IsTrue(v);
    Py_DECREF(v);
    return t;
}

/* A route (runner._direct_route): the node, its PDO engine, its write rules (the bound method in
 * its write callbacks), SimNode.on_rpdo, and what the node sets once in __init__: its write
 * callbacks list, data store, param() cache, statistics, fault switches, and its lock's acquire
 * and release; then its class's on_write function when that is a pure check (else None) and
 * the node's dict of the chunks it let pass (store_rpdo's `accepted`). */
enum { R_NODE, R_ENGINE, R_WRITE_RULES, R_ON_RPDO, R_CALLBACKS, R_STORE, R_PARAMS, R_STATS, R_FAULTS, R_ACQUIRE,
       R_RELEASE, R_PURE_ON_WRITE, R_ACCEPTED, R_SIZE };

/* The frame's RPDO codec when it takes runner.Simulator._route_frames's direct path (a live
 * node, OPERATIONAL, its RPDO compiled, the frame long enough, the node's write rules its only
 * write callback, on_rpdo not wrapped by a line gate): 1 with a new reference in *codec_out, 0
 * when Python is to handle the frame, -1 on an exception. Nothing is changed before it says 1. */
static int direct_rpdo(PyObject **route, PyObject *cid, PyObject *data, long operational, PyObject **codec_out) {
    PyObject *node = route[R_NODE], *callbacks = route[R_CALLBACKS];
    if (!PyList_Check(callbacks) || PyList_GET_SIZE(callbacks) != 1 || PyList_GET_ITEM(callbacks, 0) != route[R_WRITE_RULES])
        return 0;
    int t = attr_true(node, s_powered);
    if (t <= 0)
        return t;
    t = attr_true(route[R_FAULTS], s_silent);
    if (t != 0)
        return t < 0 ? -1 : 0;
    /* node.on_rpdo is SimNode's (a line gate in the instance, a subclass's own: Python's call) */
    PyObject *on_rpdo = PyObject_GetAttr(node, s_on_rpdo);
    if (on_rpdo == NULL)
        return -1;
    t = PyMethod_Check(on_rpdo) && PyMethod_GET_FUNCTION(on_rpdo) == route[R_ON_RPDO] && PyMethod_GET_SELF(on_rpdo) == node;
    Py_DECREF(on_rpdo);
    if (!t)
        return 0;
    PyObject *state = PyObject_GetAttr(node, s_nmt_state);
    if (state == NULL)
        return -1;
    long nmt = PyLong_Check(state) ? PyLong_AsLong(state) : -1;
    Py_DECREF(state);
    if (nmt != operational)
        return PyErr_Occurred() ? -1 : 0;
    PyObject *rpdos = PyObject_GetAttr(route[R_ENGINE], s_rpdos);
    if (rpdos == NULL)
        return -1;
    PyObject *pdo = PyDict_Check(rpdos) ? PyDict_GetItemWithError(rpdos, cid) : NULL;
    PyObject *codec = pdo != NULL ? PyObject_GetAttr(pdo, s_codec) : NULL;
    Py_DECREF(rpdos);
    if (codec == NULL)
        return PyErr_Occurred() ? -1 : 0;
    if (!PyTuple_Check(codec)) {
        Py_DECREF(codec);
        return 0;
    }
    if (PyTuple_GET_SIZE(codec) > 0) {           /* the mapped length: the last entry's end */
        PyObject *last = PyTuple_GET_ITEM(codec, PyTuple_GET_SIZE(codec) - 1);
        Py_ssize_t size = PyObject_Length(data);
        Py_ssize_t end = PyTuple_Check(last) && PyTuple_GET_SIZE(last) == 8 ? PyLong_AsSsize_t(PyTuple_GET_ITEM(last, 3)) : -1;
        if (size < 0 || end < 0 || size < end) {
            Py_DECREF(codec);
            return PyErr_Occurred() ? -1 : 0;
        }
    }
    *codec_out = codec;
    return 1;
}

/* One RPDO on the direct path, as PdoEngine.on_rpdo stores it: the frame counted, then under
 * the node's lock with in_rpdo set, store_rpdo. 0, or -1 with an exception set (the lock
 * released and in_rpdo cleared, as on_rpdo's `finally`). */
static int route_rpdo(PyObject **route, PyObject *data, PyObject *codec, PyObject *sim_stats, PyObject *aborted) {
    PyObject *node = route[R_NODE], *stats = route[R_STATS];
    if (count_up(sim_stats, s_rx_frames) < 0 || count_up(stats, s_rx_frames) < 0)
        return -1;
    PyObject *on_write = PyObject_GetAttr(node, s_on_write);
    if (on_write == NULL)
        return -1;
    PyObject *got = PyObject_CallNoArgs(route[R_ACQUIRE]);
    if (got == NULL) {
        Py_DECREF(on_write);
        return -1;
    }
    Py_DECREF(got);
    int rc = -1;
    /* the memo only while node.on_write is the class's pure check (not one patched in or overridden) */
    PyObject *accepted = route[R_PURE_ON_WRITE] != Py_None && PyDict_Check(route[R_ACCEPTED]) &&
                         PyMethod_Check(on_write) && PyMethod_GET_FUNCTION(on_write) == route[R_PURE_ON_WRITE] &&
                         PyMethod_GET_SELF(on_write) == node ? route[R_ACCEPTED] : NULL;
    if (PyObject_SetAttr(node, s_in_rpdo, Py_True) == 0)
        rc = store_rpdo(codec, data, route[R_STORE], route[R_PARAMS], on_write, route[R_WRITE_RULES], aborted, stats,
                        accepted);
    Py_DECREF(on_write);
    PyObject *type, *value, *tb;                      /* the finally: keep the exception aside */
    PyErr_Fetch(&type, &value, &tb);
    int cleared = PyObject_SetAttr(node, s_in_rpdo, Py_False);
    PyObject *released = PyObject_CallNoArgs(route[R_RELEASE]);
    if (type != NULL) {
        Py_XDECREF(released);
        PyErr_Restore(type, value, tb);     /* the first exception wins, as in Python's finally */
        return -1;
    }
    if (cleared < 0 || released == NULL) {
        Py_XDECREF(released);
        return -1;
    }
    Py_DECREF(released);
    return rc;
}

/* rpdo_burst(frames, start, routes, sim_stats, aborted, operational) -> next, or (i, exception)
 * runner.Simulator._route_frames's direct path for a burst of (cob_id, data) frames from
 * frames[start]: each RPDO of `routes` ({cob_id: route}, R_* above) that direct_rpdo takes is counted and stored as PdoEngine.on_rpdo
 * does. Returns the index of the first frame left to Python (len(frames): none), or (i, exc)
 * when frame i raised an Exception (its cleanup done; the frames before it are handled). The
 * caller holds the simulator's SYNC lock. */
static PyObject *rpdo_burst(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    (void)self;
    if (nargs != 6 || !PyDict_Check(args[2])) {
        PyErr_SetString(PyExc_TypeError, "rpdo_burst(frames, start, routes, sim_stats, aborted, operational)");
        return NULL;
    }
    PyObject *routes = args[2], *sim_stats = args[3], *aborted = args[4];
    Py_ssize_t start = PyLong_AsSsize_t(args[1]);
    long operational = PyLong_AsLong(args[5]);
    if (PyErr_Occurred())
        return NULL;
    PyObject *frames = PySequence_Fast(args[0], "frames must be a sequence");
    if (frames == NULL)
        return NULL;
    Py_ssize_t n = PySequence_Fast_GET_SIZE(frames), i = start < 0 ? 0 : start;
    for (; i < n; i++) {
        PyObject *frame = PySequence_Fast_GET_ITEM(frames, i);
        if (!PyTuple_Check(frame) || PyTuple_GET_SIZE(frame) != 2)
            break;
        PyObject *cid = PyTuple_GET_ITEM(frame, 0), *data = PyTuple_GET_ITEM(frame, 1);
        PyObject *route = PyDict_GetItemWithError(routes, cid);
        if (route == NULL) {
            if (PyErr_Occurred())
                goto error;
            break;
        }
        if (!PyTuple_Check(route) || PyTuple_GET_SIZE(route) != R_SIZE)
            break;
        PyObject **items = &PyTuple_GET_ITEM(route, 0), *codec = NULL;
        int direct = direct_rpdo(items, cid, data, operational, &codec);
        if (direct < 0)
            goto error;
        if (direct == 0)
            break;
        int rc = route_rpdo(items, data, codec, sim_stats, aborted);
        Py_DECREF(codec);
        if (rc < 0)
            goto error;
    }
    Py_DECREF(frames);
    return PyLong_FromSsize_t(i);
error:
    Py_DECREF(frames);
    if (!PyErr_ExceptionMatches(PyExc_Exception))
        return NULL;                        /* KeyboardInterrupt and the like: not the frame's */
    PyObject *type, *value, *tb;
    PyErr_Fetch(&type, &value, &tb);
    PyErr_NormalizeException(&type, &value, &tb);
    if (tb != NULL)
        PyException_SetTraceback(value, tb);
    Py_XDECREF(type);
    Py_XDECREF(tb);
    PyObject *out = Py_BuildValue("(nN)", i, value);
    return out;
}

/* tpdo_frames(table, counter) -> [(cob_id, bytes), ...] or None
 * PdoEngine.send_tpdos's due TPDOs sampled: table = ((cob_id, transmission type, dicts, subs),
 * ...) with each mapped object's data-store dict and subindex (PdoEngine._slots); a TPDO is due
 * at this SYNC counter when synchronous (0..240) and, beyond type 1, every type-th SYNC. Its
 * bytes are the mapped objects' stored bytes joined. None when an object is not stored as
 * bytes (the Python path samples it through SimNode.raw). */
static PyObject *sample_tpdos(PyObject *table, long long counter);

static PyObject *tpdo_frames(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    (void)self;
    if (nargs != 2 || !PyTuple_Check(args[0])) {
        PyErr_SetString(PyExc_TypeError, "tpdo_frames(table, counter)");
        return NULL;
    }
    long long counter = PyLong_AsLongLong(args[1]);
    if (counter == -1 && PyErr_Occurred())
        return NULL;
    return sample_tpdos(args[0], counter);
}

/* tpdo_frames' work: a new list, None (new reference), or NULL with an exception set */
static PyObject *sample_tpdos(PyObject *table, long long counter) {
    PyObject *frames = PyList_New(0);
    if (frames == NULL)
        return NULL;
    for (Py_ssize_t t = 0; t < PyTuple_GET_SIZE(table); t++) {
        PyObject *row = PyTuple_GET_ITEM(table, t);
        if (!PyTuple_Check(row) || PyTuple_GET_SIZE(row) != 4 || !PyTuple_Check(PyTuple_GET_ITEM(row, 2)) ||
            !PyTuple_Check(PyTuple_GET_ITEM(row, 3)) ||
            PyTuple_GET_SIZE(PyTuple_GET_ITEM(row, 2)) != PyTuple_GET_SIZE(PyTuple_GET_ITEM(row, 3))) {
            Py_DECREF(frames);
            PyErr_SetString(PyExc_TypeError, "tpdo_frames: rows are (cob_id, type, dicts, subs)");
            return NULL;
        }
        long long type = PyLong_AsLongLong(PyTuple_GET_ITEM(row, 1));
        if (type == -1 && PyErr_Occurred()) {
            Py_DECREF(frames);
            return NULL;
        }
        if (type < 0 || type > 240 || (type > 1 && counter % type))
            continue;
        PyObject *dicts = PyTuple_GET_ITEM(row, 2), *subs = PyTuple_GET_ITEM(row, 3);
        Py_ssize_t n = PyTuple_GET_SIZE(dicts), total = 0;
        PyObject *parts[64];
        if (n > 64)
            goto python;
        for (Py_ssize_t i = 0; i < n; i++) {
            PyObject *d = PyTuple_GET_ITEM(dicts, i);
            PyObject *part = PyDict_Check(d) ? PyDict_GetItemWithError(d, PyTuple_GET_ITEM(subs, i)) : NULL;
            if (part == NULL || !PyBytes_Check(part)) {
                if (PyErr_Occurred()) {
                    Py_DECREF(frames);
                    return NULL;
                }
                goto python;
            }
            parts[i] = part;
            total += PyBytes_GET_SIZE(part);
        }
        PyObject *data = PyBytes_FromStringAndSize(NULL, total);
        if (data == NULL) {
            Py_DECREF(frames);
            return NULL;
        }
        char *out = PyBytes_AS_STRING(data);
        for (Py_ssize_t i = 0; i < n; i++) {       /* total is the sum of these sizes */
            memcpy(out, PyBytes_AS_STRING(parts[i]), PyBytes_GET_SIZE(parts[i]));
            out += PyBytes_GET_SIZE(parts[i]);
        }
        PyObject *frame = PyTuple_Pack(2, PyTuple_GET_ITEM(row, 0), data);
        Py_DECREF(data);
        if (frame == NULL || PyList_Append(frames, frame) < 0) {
            Py_XDECREF(frame);
            Py_DECREF(frames);
            return NULL;
        }
        Py_DECREF(frame);
    }
    return frames;
python:
    Py_DECREF(frames);
    Py_RETURN_NONE;
}

/* A node's TPDO route (runner._tpdo_route): the node, its PDO engine, its LocalNode, its lock's
 * acquire and release, SimNode.send_tpdos, and the simulator's send_many as the node holds it. */
enum { T_NODE, T_ENGINE, T_LOCAL, T_ACQUIRE, T_RELEASE, T_SEND_TPDOS, T_SEND_MANY, T_SIZE };

/* 1: attr is a bound method of `self` whose function is `func` */
static int bound_to(PyObject *self, PyObject *name, PyObject *func) {
    PyObject *m = PyObject_GetAttr(self, name);
    if (m == NULL)
        return -1;
    int t = PyMethod_Check(m) && PyMethod_GET_FUNCTION(m) == func && PyMethod_GET_SELF(m) == self;
    Py_DECREF(m);
    return t;
}

/* 1: obj.name is the int `value` */
static int attr_is_long(PyObject *obj, PyObject *name, long value) {
    PyObject *v = PyObject_GetAttr(obj, name);
    if (v == NULL)
        return -1;
    long x = PyLong_Check(v) ? PyLong_AsLong(v) : value - 1;
    Py_DECREF(v);
    if (x == -1 && PyErr_Occurred())
        return -1;
    return x == value;
}

/* The node's compiled TPDO table (PdoEngine._core_table's rows, new reference) when its SYNC's
 * TPDOs take the direct path: send_tpdos not wrapped (line gate) or overridden, OPERATIONAL and
 * not ignoring SYNC, the table read and its rows current (the store generation they were made
 * for), no SDO-answer COB-ID among them, no fault switch on its frames, no read callbacks, and
 * the node sending through the simulator's send_many. NULL without an exception: Python's. */
static PyObject *direct_tpdo_rows(PyObject **route, PyObject *faults, long operational) {
    PyObject *node = route[T_NODE], *engine = route[T_ENGINE];
    if (bound_to(node, s_send_tpdos, route[T_SEND_TPDOS]) != 1 || attr_is_long(node, s_nmt_state, operational) != 1 ||
        attr_true(faults, s_ignore_sync) != 0 || attr_true(faults, s_drop_tx) != 0 ||
        attr_true(faults, s_corrupt_tx) != 0 || attr_true(engine, s_plain_cobs) != 1 ||
        attr_true(route[T_LOCAL], s_read_callbacks) != 0 || attr_true(node, s_powered) != 1)
        return NULL;
    PyObject *send = PyObject_GetAttr(node, s_send), *send_many = PyObject_GetAttr(node, s_send_many_name);
    int sends = send != NULL && send != Py_None && send_many == route[T_SEND_MANY];
    Py_XDECREF(send);
    Py_XDECREF(send_many);
    if (!sends)
        return NULL;
    PyObject *tpdos = PyObject_GetAttr(engine, s_tpdos), *key = PyObject_GetAttr(engine, s_core_key);
    PyObject *generation = PyObject_GetAttr(node, s_store_generation);
    PyObject *rows = NULL;
    if (tpdos != NULL && tpdos != Py_None && key != NULL && PyTuple_Check(key) && PyTuple_GET_SIZE(key) == 2 &&
        PyTuple_GET_ITEM(key, 0) == tpdos && generation != NULL &&
        PyObject_RichCompareBool(PyTuple_GET_ITEM(key, 1), generation, Py_EQ) == 1) {
        rows = PyObject_GetAttr(engine, s_core_rows);
        if (rows != NULL && !PyTuple_Check(rows))
            Py_CLEAR(rows);
    }
    Py_XDECREF(tpdos);
    Py_XDECREF(key);
    Py_XDECREF(generation);
    return rows;
}

/* obj.name += n */
static int add_to(PyObject *obj, PyObject *name, Py_ssize_t n) {
    PyObject *v = PyObject_GetAttr(obj, name);
    if (v == NULL)
        return -1;
    PyObject *k = PyLong_FromSsize_t(n);
    PyObject *sum = k != NULL ? PyNumber_Add(v, k) : NULL;
    Py_DECREF(v);
    Py_XDECREF(k);
    if (sum == NULL)
        return -1;
    int rc = PyObject_SetAttr(obj, name, sum);
    Py_DECREF(sum);
    return rc;
}

/* tpdo_burst(nodes, start, routes, batch, operational) -> next
 * runner.Simulator._sync_step's TPDO loop from nodes[start]: a silent node sends nothing; a
 * node of `routes` ({node: route}, T_* above) that takes the direct path (direct_tpdo_rows,
 * and every mapped object stored) has its SYNC counted and its due TPDOs sampled under its lock
 * (tpdo_frames) and appended to `batch`, the SYNC's burst, as PdoEngine.send_tpdos and
 * SimNode.send_frames do. Returns the index of the first node left to Python (len(nodes):
 * none); a node is left to Python untouched. The caller batches this SYNC's frames. */
static PyObject *tpdo_burst(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    (void)self;
    if (nargs != 5 || !PyDict_Check(args[2]) || !PyList_Check(args[3])) {
        PyErr_SetString(PyExc_TypeError, "tpdo_burst(nodes, start, routes, batch, operational)");
        return NULL;
    }
    PyObject *routes = args[2], *batch = args[3];
    Py_ssize_t start = PyLong_AsSsize_t(args[1]);
    long operational = PyLong_AsLong(args[4]);
    if (PyErr_Occurred())
        return NULL;
    PyObject *nodes = PySequence_Fast(args[0], "nodes must be a sequence");
    if (nodes == NULL)
        return NULL;
    Py_ssize_t n = PySequence_Fast_GET_SIZE(nodes), i = start < 0 ? 0 : start;
    for (; i < n; i++) {
        PyObject *route = PyDict_GetItemWithError(routes, PySequence_Fast_GET_ITEM(nodes, i));
        if (route == NULL || !PyTuple_Check(route) || PyTuple_GET_SIZE(route) != T_SIZE)
            break;
        PyObject **r = &PyTuple_GET_ITEM(route, 0);
        PyObject *faults = PyObject_GetAttr(r[T_NODE], s_faults);
        int silent = faults != NULL ? attr_true(faults, s_silent) : -1;
        if (silent != 0) {
            Py_XDECREF(faults);
            if (silent < 0)
                goto error;
            continue;                                   /* the SYNC loop skips it */
        }
        PyObject *rows = direct_tpdo_rows(r, faults, operational);
        Py_DECREF(faults);
        if (rows == NULL) {
            if (PyErr_Occurred())
                goto error;
            break;
        }
        PyObject *counter = PyObject_GetAttr(r[T_ENGINE], s_sync_counter);
        PyObject *next = counter != NULL ? PyNumber_Add(counter, one_) : NULL;
        Py_XDECREF(counter);
        long long count = next != NULL ? PyLong_AsLongLong(next) : -1;
        PyObject *got = count == -1 && PyErr_Occurred() ? NULL : PyObject_CallNoArgs(r[T_ACQUIRE]);
        PyObject *frames = got != NULL ? sample_tpdos(rows, count) : NULL;
        Py_XDECREF(got);
        Py_DECREF(rows);
        if (got != NULL) {
            PyObject *type, *value, *tb;
            PyErr_Fetch(&type, &value, &tb);
            PyObject *released = PyObject_CallNoArgs(r[T_RELEASE]);
            if (type != NULL) {
                Py_XDECREF(released);
                PyErr_Restore(type, value, tb);
            } else if (released == NULL) {
                Py_CLEAR(frames);
            } else {
                Py_DECREF(released);
            }
        }
        if (frames == NULL || frames == Py_None) {      /* an object not stored: Python samples it */
            Py_XDECREF(next);
            Py_XDECREF(frames);
            if (PyErr_Occurred())
                goto error;
            break;
        }
        Py_ssize_t sent = PyList_GET_SIZE(frames);
        PyObject *stats = PyObject_GetAttr(r[T_NODE], s_stats);
        int rc = stats != NULL ? PyObject_SetAttr(r[T_ENGINE], s_sync_counter, next) : -1;
        Py_DECREF(next);
        if (rc == 0)
            rc = count_up(stats, s_syncs);
        if (rc == 0 && sent > 0)
            rc = PyList_SetSlice(batch, PyList_GET_SIZE(batch), PyList_GET_SIZE(batch), frames);
        if (rc == 0 && sent > 0)
            rc = add_to(stats, s_tx_frames, sent);
        Py_XDECREF(stats);
        Py_DECREF(frames);
        if (rc < 0)
            goto error;
    }
    Py_DECREF(nodes);
    return PyLong_FromSsize_t(i);
error:
    Py_DECREF(nodes);
    return NULL;
}

/* statusword bits (base/canopen/cia402_defs.py) */
#define SW_WARNING (1 << 7)
#define SW_REMOTE (1 << 9)
#define SW_TARGET_REACHED (1 << 10)
#define SW_INTERNAL_LIMIT (1 << 11)
#define SW_OP_MODE_12 (1 << 12)
#define SW_FOLLOWING_ERROR (1 << 13)
/* drive_end's flags */
#define END_ENERGISED 1
#define END_ENABLED 2
#define END_FAULT_REACTION 4
#define END_QUICK_STOP 8
#define END_RAMP_FROM_ACTUAL 16
#define END_LIMIT_ACTIVE 32

/* drive_end(dt, flags, quick_stop_option, v_ref, brake_closing, brake_engage, q_ref, q_measured,
 *           fe_window, fe_time, fe_timeout_ms, temperature, over_temperature, warn_temperature,
 *           state_bits, k, rated, q_reported, qd_reported, torque_reported)
 * JointDriveNode.on_sync_end in CSP for a SYNC that changes no state: the brake's timing
 * (_stop_and_brake), the following error, the statusword and the actual values (_update_od).
 * -> (brake_closing, brake engaged, fe_time, following_error, statusword, position, demand,
 * velocity, torque, following error count, temperature count), or None when the drive leaves
 * its state (a stop ends, a following-error timeout, over temperature) or a value is not finite:
 * the Python path runs the SYNC end. */
/* drive_end's work on its 20 arguments: 1 with the results in *o, 0 for None (the Python path's
 * SYNC end), -1 with an exception set */
struct end_out {
    double brake_closing, fe_time;
    int engaged, following_error;
    long sw;
    long long v[6];
};

static int end_compute(PyObject *const *args, struct end_out *o) {
    long flags = PyLong_AsLong(args[1]), option = PyLong_AsLong(args[2]), state_bits = PyLong_AsLong(args[14]);
    double a[20];
    for (int i = 0; i < 20; i++)
        a[i] = (i == 1 || i == 2 || i == 14) ? 0.0 : PyFloat_AsDouble(args[i]);
    if (PyErr_Occurred())
        return -1;
    const double dt = a[0], v_ref = a[3], brake_engage = a[5], q_ref = a[6], q_measured = a[7], fe_window = a[8];
    const double fe_timeout_ms = a[10], temperature = a[11], over_temperature = a[12], warn_temperature = a[13];
    const double k = a[15], rated = a[16];
    double brake_closing = a[4], fe_time = a[9];
    const int enabled = (flags & END_ENABLED) != 0;
    /* _stop_and_brake */
    int at_rest = v_ref == 0.0 && !(flags & END_RAMP_FROM_ACTUAL);
    int letting_go = ((flags & END_FAULT_REACTION) && at_rest) ||
                     ((flags & END_QUICK_STOP) && at_rest && option >= 1 && option <= 4);
    if (!(flags & END_ENERGISED) || letting_go)
        brake_closing += dt;
    else
        brake_closing = 0.0;
    int engaged = brake_closing >= brake_engage;
    if (letting_go && engaged)
        return 0;                           /* the stop ends: the drive leaves operation */
    /* following error */
    double err = q_ref - q_measured;
    int following_error;
    if (enabled && fabs(err) > fe_window) {
        fe_time += dt;
        following_error = 1;
        if (fe_time * 1000.0 > fe_timeout_ms)
            return 0;                       /* the drive faults */
    } else {
        fe_time = 0.0;
        following_error = 0;
    }
    if (temperature > over_temperature)
        return 0;
    /* _update_od's statusword (CSP) */
    long sw = state_bits | SW_REMOTE;
    if (flags & END_LIMIT_ACTIVE)
        sw |= SW_INTERNAL_LIMIT;
    if (following_error)
        sw |= SW_FOLLOWING_ERROR;
    if (temperature > warn_temperature)
        sw |= SW_WARNING;
    if (enabled)
        sw |= SW_OP_MODE_12;
    if (!following_error && !enabled)
        sw |= SW_TARGET_REACHED;
    if (!actual_counts(k, rated, a[17], q_ref, a[18], a[19], q_measured, temperature, o->v))
        return 0;
    o->brake_closing = brake_closing;
    o->fe_time = fe_time;
    o->engaged = engaged;
    o->following_error = following_error;
    o->sw = sw;
    return 1;
}

static PyObject *drive_end(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    (void)self;
    if (nargs != 20) {
        PyErr_Format(PyExc_TypeError, "drive_end takes 20 arguments (%zd given)", nargs);
        return NULL;
    }
    struct end_out o;
    int rc = end_compute(args, &o);
    if (rc < 0)
        return NULL;
    if (rc == 0)
        Py_RETURN_NONE;
    return Py_BuildValue("(dOdOlLLLLLL)", o.brake_closing, o.engaged ? Py_True : Py_False, o.fe_time,
                         o.following_error ? Py_True : Py_False, o.sw, o.v[0], o.v[1], o.v[2], o.v[3], o.v[4], o.v[5]);
}

/* drive_end_write(<drive_end's 20 arguments>, mode, error_code, specs, entries, last_values,
 *                 last_stored, params)
 * drive_end and the drive's CyclicObjects.write of (statusword, mode, the six counts, brake
 * 1/0, error_code) in one call (issue 35: a Python write and two tuples per drive and SYNC);
 * specs .. params: the CyclicObjects' layout and state (cyclic_write's), its store generation
 * current (the caller checks). -> (brake_closing, brake engaged, fe_time, following_error,
 * stop, values): stop is where the write stopped (len(values): done; else the Python loop
 * goes on from there, which raises for a value that does not fit); or None, nothing written
 * (drive_end's None). */
static PyObject *drive_end_write(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    (void)self;
    if (nargs != 27) {
        PyErr_Format(PyExc_TypeError, "drive_end_write takes 27 arguments (%zd given)", nargs);
        return NULL;
    }
    PyObject *specs = args[22], *entries = args[23], *last_values = args[24], *last_stored = args[25],
             *params = args[26];
    if (!cyclic_layout_ok(specs, 10, entries, last_values, last_stored, params)) {
        PyErr_SetString(PyExc_TypeError, "drive_end_write: layout, entries and last values do not match");
        return NULL;
    }
    struct end_out o;
    int rc = end_compute(args, &o);
    if (rc < 0)
        return NULL;
    if (rc == 0)
        Py_RETURN_NONE;
    PyObject *values = Py_BuildValue("(lOLLLLLLiO)", o.sw, args[20], o.v[0], o.v[1], o.v[2], o.v[3], o.v[4], o.v[5],
                                     o.engaged ? 1 : 0, args[21]);
    if (values == NULL)
        return NULL;
    Py_ssize_t stop = cyclic_store(specs, &PyTuple_GET_ITEM(values, 0), 10, entries, last_values, last_stored, params, 0);
    if (stop < 0) {
        Py_DECREF(values);
        return NULL;
    }
    return Py_BuildValue("(dOdOnN)", o.brake_closing, o.engaged ? Py_True : Py_False, o.fe_time,
                         o.following_error ? Py_True : Py_False, stop, values);
}

static PyMethodDef methods[] = {
    {"drive_end_write", (PyCFunction)(void (*)(void))drive_end_write, METH_FASTCALL,
     "drive_end and the drive's actual values written, in one call (see the module source)."},
    {"drive_end", (PyCFunction)(void (*)(void))drive_end, METH_FASTCALL,
     "A CSP drive's SYNC end that changes no state (see the module source)."},
    {"tpdo_burst", (PyCFunction)(void (*)(void))tpdo_burst, METH_FASTCALL,
     "runner.Simulator._sync_step's TPDO loop for the nodes on the direct path (see the module source)."},
    {"tpdo_frames", (PyCFunction)(void (*)(void))tpdo_frames, METH_FASTCALL,
     "PdoEngine.send_tpdos's due TPDOs sampled (see the module source)."},
    {"rpdo_burst", (PyCFunction)(void (*)(void))rpdo_burst, METH_FASTCALL,
     "runner.Simulator._route_frames's direct path for a burst of RPDOs (see the module source)."},
    {"rpdo_store", (PyCFunction)(void (*)(void))rpdo_store, METH_FASTCALL,
     "PdoEngine.on_rpdo's loop over the mapped objects (see the module source)."},
    {"cyclic_write", (PyCFunction)(void (*)(void))cyclic_write, METH_FASTCALL,
     "CyclicObjects.write's loop (see the module source)."},
    {"steady_begin", (PyCFunction)(void (*)(void))steady_begin, METH_FASTCALL,
     "A drive's SYNC begin that changes no state (see the module source)."},
    {"rigid_period", (PyCFunction)(void (*)(void))rigid_period, METH_FASTCALL,
     "A rigid-gear joint's SYNC period with its drive's servo law (see the module source)."},
    {"two_mass_period", (PyCFunction)(void (*)(void))two_mass_period, METH_FASTCALL,
     "A loose or elastic gear's SYNC period with its drive's servo law (see the module source)."},
    {"actual_values", (PyCFunction)(void (*)(void))actual_values, METH_FASTCALL,
     "A drive's actual values as its objects count them (see the module source)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_simcore", NULL, -1, methods};

PyMODINIT_FUNC PyInit__simcore(void) {
    struct {
        PyObject **name;
        const char *text;
    } names[] = {{&s_powered, "powered"}, {&s_faults, "faults"}, {&s_stats, "stats"}, {&s_silent, "silent"}, {&s_nmt_state, "nmt_state"},
                 {&s_rpdos, "rpdos"}, {&s_codec, "codec"}, {&s_rx_frames, "rx_frames"}, {&s_in_rpdo, "in_rpdo"},
                 {&s_on_write, "on_write"}, {&s_on_rpdo, "on_rpdo"}, {&s_send_tpdos, "send_tpdos"},
                 {&s_ignore_sync, "ignore_sync"}, {&s_drop_tx, "drop_tx"}, {&s_corrupt_tx, "corrupt_tx"},
                 {&s_plain_cobs, "_plain_cobs"}, {&s_read_callbacks, "_read_callbacks"}, {&s_send, "_send"},
                 {&s_send_many_name, "_send_many"}, {&s_tpdos, "tpdos"}, {&s_core_key, "_core_key"},
                 {&s_store_generation, "store_generation"}, {&s_core_rows, "_core_rows"},
                 {&s_sync_counter, "sync_counter"}, {&s_syncs, "syncs"}, {&s_tx_frames, "tx_frames"}};
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++)
        if ((*names[i].name = PyUnicode_InternFromString(names[i].text)) == NULL)
            return NULL;
    if ((one_ = PyLong_FromLong(1)) == NULL)
        return NULL;
    return PyModule_Create(&module);
}
