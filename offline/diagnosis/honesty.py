"""What the diagnosis may claim: only joints that moved, only effects whose size is known
better than its own value, only fits the held-out re-simulation confirms, and every law
that explains the data as well as the chosen one named beside it."""
from __future__ import annotations

import numpy as np

from spacearm.offline.diagnosis.candidates import VELOCITY_DEADBAND
from spacearm.offline.diagnosis.fitting import ChannelFit, common_block

MIN_TRAVEL = 0.005           # rad: a joint that moved less never excited friction or load
MIN_MOVING_FRACTION = 0.05   # of the rows
EQUAL_EVIDENCE = 6.0         # BIC within this of the best (below "strong" evidence): explains the data as well
ONE_SPEED_BAND = 0.15        # |v| within +-15 % of the median speed ...
ONE_SPEED_FRACTION = 0.8     # ... on this share of the moving rows: one speed only
MIN_CONFIRMED_REDUCTION = 0.05   # held-out re-simulation must lower the channel's RMS at least this much
FRICTION = ("coulomb", "viscous", "stribeck")


def moved(q: np.ndarray, dq: np.ndarray) -> bool:
    """Whether a joint moved enough in the recording (measured q) and its nominal replay (dq)."""
    return bool(np.ptp(q) > MIN_TRAVEL and np.mean(np.abs(dq) > VELOCITY_DEADBAND) > MIN_MOVING_FRACTION)


def single_speed(dq: np.ndarray) -> float | None:
    """The speed if the joint moved at essentially one speed (a constant-speed ramp), else None."""
    v = np.abs(dq[np.abs(dq) > VELOCITY_DEADBAND])
    if len(v) < 10:
        return None
    median = float(np.median(v))
    return median if np.mean(np.abs(v - median) <= ONE_SPEED_BAND * median) >= ONE_SPEED_FRACTION else None


def one_way(dq: np.ndarray) -> bool:
    v = dq[np.abs(dq) > VELOCITY_DEADBAND]
    return len(v) > 0 and bool(np.all(v > 0) or np.all(v < 0))


def count_reversals(v: np.ndarray) -> int:
    """Velocity sign changes between real motions (a quarter of the top speed: the servo's
    settling wiggle from the first measured position is no reversal)."""
    moving = v[np.abs(v) > max(VELOCITY_DEADBAND, 0.25 * float(np.max(np.abs(v))))]
    return int(np.count_nonzero(np.diff(np.sign(moving))))


def equally_good(best: ChannelFit, ranked: list[ChannelFit], dq: np.ndarray) -> list[ChannelFit]:
    """Other explanations of the same channel that the recording cannot tell from the best:
    BIC within EQUAL_EVIDENCE of it (at one block length), or, at one speed, the other friction law (Coulomb
    and viscous friction are both a constant drag there), or, one way only, Coulomb for
    Stribeck and back (the stiction bump needs starts from rest in both directions to show),
    or a constant force along a slide for friction and back (see same_drag). At most two laws,
    and a constant force beside them: the one explanation that is no friction at all."""
    out: list[ChannelFit] = []
    block = common_block([best] + ranked)
    friction_only = set(best.effects) <= set(FRICTION)
    for f in ranked:
        if f is best or set(f.effects) == set(best.effects) or f.channel != best.channel:
            continue
        close = f.bic_at(block) - best.bic_at(block) < EQUAL_EVIDENCE
        same_family = friction_only and set(f.effects) <= set(FRICTION) and len(f.effects) == 1
        if close or (same_family and (single_speed(dq) is not None or one_way(dq))) or same_drag(best, f, dq):
            if all(set(f.effects) != set(o.effects) for o in out):
                out.append(f)
    return [f for f in out if not constant_force(f)][:2] + [f for f in out if constant_force(f)]


def stiction_unseparated(best: ChannelFit, dq: np.ndarray, alternatives: list[ChannelFit]) -> float | None:
    """The one speed of a joint whose running friction law (`best`, Coulomb or viscous) a
    Stribeck law falling to the same level would fit as well, where none is named beside it
    yet: at one speed the two differ only in the breakaway at the few starts and reversals, and
    the diagnosis' breakaway test (stick_slip.py) did not find it there. None otherwise, and
    on motion one way only: there a stiction law's size is not known at all (one start), and
    such a law is not named beside the choice (analysis.py)."""
    if best.channel != "tau" or not set(best.effects) <= {"coulomb", "viscous"} or count_reversals(dq) == 0 or \
            any("stribeck" in f.effects for f in alternatives):
        return None
    return single_speed(dq)


def constant_force(fit: ChannelFit) -> bool:
    """A load fitted as one constant force along a prismatic joint's axis."""
    return fit.effects == ("gravity_load",) and "load_force" in fit.columns


def same_drag(a: ChannelFit, b: ChannelFit, dq: np.ndarray) -> bool:
    """Whether one of the two is a constant force along a slide and the other a friction law
    the motion cannot tell from it: one way only, Coulomb friction is the same constant (and
    Stribeck friction with it, see above), and at one speed viscous friction too. One way:
    no reversal between real motions (the servo's settling wiggle at the start is none)."""
    if count_reversals(dq) > 0 or constant_force(a) == constant_force(b):
        return False
    friction = b if constant_force(a) else a
    return friction.effects in (("coulomb",), ("stribeck",)) or \
        (friction.effects == ("viscous",) and single_speed(dq) is not None)


def uncertain(values: dict[str, float], errors: dict[str, float]) -> bool:
    """Whether no size of the effect is known to be there: every parameter's standard error
    is more than half its value (a drift with a zero offset is still a drift)."""
    known = [k for k, e in errors.items() if k in values and np.isfinite(e)]
    return bool(known) and all(abs(values[k]) < 2.0 * errors[k] for k in known)


def _centred(fit: ChannelFit, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, float] | None:
    """A rotary joint's load fit as its torque at the centre of the travel (q: the joint's
    positions) and that torque's slope along q, with their standard errors, and the centre;
    None for any other fit. Over a short stroke a load's cos and sin parts are a constant and
    a slope: the slope, and with it the amplitude and angle, is poorly known while the constant
    is not; over a long one either may be the part that is known."""
    if fit.effects != ("gravity_load",) or fit.correlation is None or "load_cos" not in fit.columns:
        return None
    i, k = fit.columns.index("load_cos"), fit.columns.index("load_sin")
    centre = float(np.mean(q))
    # torque c cos q - s sin q and its derivative -c sin q - s cos q, at the centre
    rotate = np.array([[np.cos(centre), -np.sin(centre)], [-np.sin(centre), -np.cos(centre)]])
    sd = fit.stderr[[i, k]]
    if not (np.all(np.isfinite(sd)) and np.all(np.isfinite(fit.coef[[i, k]]))):
        return None              # no error to judge by: the amplitude's own test decides
    cov = rotate @ (fit.correlation[np.ix_([i, k], [i, k])] * np.outer(sd, sd)) @ rotate.T
    return rotate @ fit.coef[[i, k]], np.sqrt(np.clip(np.diag(cov), 0.0, None)), centre


def load_at_centre(fit: ChannelFit, q: np.ndarray) -> tuple[float, float, float] | None:
    """A rotary joint's load fit as (torque at the centre of the travel, its standard error,
    the centre); None for any other fit (see _centred)."""
    at = _centred(fit, q)
    return None if at is None else (float(at[0][0]), float(at[1][0]), at[2])


def load_unknown(fit: ChannelFit, q: np.ndarray) -> bool | None:
    """Whether a load on a rotary joint is not known to be there by its torque at the centre of
    the travel or by that torque's slope: both within two standard errors of zero. None: no
    such load fit. Judged by its amplitude alone, a load 5x its noise along a Panda motion went
    unreported (amplitude 4.9 +- 19 N m, its torque over the stroke 3.5 +- 0.4 N m)."""
    at = _centred(fit, q)
    return None if at is None else bool(np.all(np.abs(at[0]) <= 2.0 * at[1]))


def confirmed(rms_before: float, rms_after: float) -> bool:
    return rms_after <= (1.0 - MIN_CONFIRMED_REDUCTION) * rms_before
