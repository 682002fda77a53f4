"""The supervisor's position and velocity test as Python floats (_Bounds.outside) answers as the
numpy comparisons of its findings do: on random joints near and beyond their bounds, NaN and
infinities included, and on inputs it leaves to numpy (other dtypes, shapes)."""
import numpy as np

from spacearm.controller.cycle import Measurement
from spacearm.controller.daemon.supervision import SupervisionLimits, Supervisor


def measurement(q, dq) -> Measurement:
    n = len(q)
    return Measurement(time=0.0, sync_counter=0, q=q, dq=dq, tau=np.zeros(n),
                       joints_enabled=np.ones(n, bool), joints_faulted=np.zeros(n, bool), wrench=np.zeros(6))


def numpy_says_outside(bounds, q, dq) -> bool:
    return bool(np.count_nonzero(q < bounds.q_low) or np.count_nonzero(q > bounds.q_high)
                or np.count_nonzero(np.abs(dq) > bounds.v_high))


def test_plain_bounds_answer_as_numpy_and_the_findings_follow() -> None:
    rng = np.random.default_rng(35)
    n = 6
    limits = SupervisionLimits(-rng.uniform(1, 3, n), rng.uniform(1, 3, n), rng.uniform(0.5, 2, n))
    supervisor = Supervisor(limits, [f"j{i}" for i in range(n)])
    bounds = supervisor._bounds_of(limits)
    special = np.array([np.nan, np.inf, -np.inf, 0.0, -0.0])
    seen = set()
    for _ in range(3000):
        q = rng.uniform(-1.0, 1.0, n)       # inside every bound
        dq = rng.uniform(-0.5, 0.5, n)
        if rng.random() < 0.4:      # one joint anywhere near its bounds
            q[rng.integers(n)] = rng.uniform(-3.5, 3.5)
            dq[rng.integers(n)] = rng.uniform(-2.5, 2.5)
        if rng.random() < 0.2:
            q[rng.integers(n)] = rng.choice(special)
            dq[rng.integers(n)] = rng.choice(special)
        if rng.random() < 0.2:      # exactly on a bound
            i = rng.integers(n)
            q[i] = bounds.q_low[i] if rng.random() < 0.5 else bounds.q_high[i]
            dq[i] = bounds.v_high[i] * rng.choice([-1.0, 1.0])
        expected = numpy_says_outside(bounds, q, dq)
        assert bounds.outside(q, dq) == expected
        seen.add(expected)
        findings = [f for f in supervisor.check(measurement(q, dq), None, False)
                    if f.code in ("position_limit", "velocity_limit")]
        assert bool(findings) == expected
    assert seen == {True, False}


def test_inputs_it_cannot_compare_plainly_go_to_numpy() -> None:
    n = 3
    limits = SupervisionLimits(np.full(n, -1.0), np.full(n, 1.0), np.ones(n))
    supervisor = Supervisor(limits, ["a", "b", "c"])
    bounds = supervisor._bounds_of(limits)
    zeros = np.zeros(n)
    assert bounds.outside(np.zeros(n, np.float32), zeros)       # another dtype
    assert bounds.outside(zeros, [0.0, 0.0, 0.0])                 # not an array
    assert bounds.outside(np.zeros(n + 1), np.zeros(n + 1))       # another length
    assert not bounds.outside(zeros, zeros)
    # numpy still decides there: the same findings as before
    findings = supervisor.check(measurement(np.array([0.0, 2.0, 0.0], np.float32), [0.0, 0.0, 3.0]), None, False)
    assert [f.code for f in findings] == ["position_limit", "velocity_limit"]
