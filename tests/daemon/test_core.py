"""Controller core: states, protective stop with kept reason, motion only after reset."""
from __future__ import annotations

import threading

import numpy as np
import pytest

from spacearm.controller.daemon.core import CommandRefused, ControllerCore
from spacearm.controller.modes import PlannedMode
from spacearm.controller.cycle import DeviceEvent, Measurement
from spacearm.controller.daemon.supervision import SupervisionLimits, Supervisor
from spacearm.controller.planning.joint_move import JointLimits, JointMove

N = 6
NAMES = [f"j{i + 1}" for i in range(N)]
LIMITS = JointLimits(np.full(N, -3.0), np.full(N, 3.0), np.full(N, 0.2), np.full(N, 0.4), np.full(N, 2.0))


def measurement(t, q=None, enabled=True, **kw):
    return Measurement(time=t, sync_counter=int(round(t / 0.02)) % 256,
                       q=np.zeros(N) if q is None else q, dq=kw.pop("dq", np.zeros(N)), tau=np.zeros(N),
                       joints_enabled=np.full(N, enabled), joints_faulted=kw.pop("faulted", np.zeros(N, bool)),
                       wrench=kw.pop("wrench", np.zeros(6)), **kw)


@pytest.fixture
def core():
    sup = Supervisor(SupervisionLimits(LIMITS.q_min, LIMITS.q_max, LIMITS.v_max), NAMES)
    return ControllerCore(sup, NAMES, 0.02)


def run_command(core, t, apply, m=None):
    """Submit from another thread while the 'cycle' (this thread) runs update()."""
    box = {}
    thread = threading.Thread(target=lambda: box.setdefault("r", _try(core.submit, apply)))
    thread.start()
    while not core.requests_waiting and thread.is_alive():
        pass
    command = core.update(m or measurement(t))
    thread.join(5)
    return box["r"], command


def _try(fn, *args):
    try:
        return fn(*args)
    except Exception as exc:
        return exc


def enable(core, t=0.0):
    result, _ = run_command(core, t, core.cmd_enable, measurement(t, enabled=False))
    assert result == "enabling"
    core.update(measurement(t + 0.02))
    assert core.state == "enabled"


def start(core, t, goal_from):
    q0, _ = run_command(core, t, core.motion_start)
    if isinstance(q0, Exception):
        return q0, None
    mode = PlannedMode("move_joints", JointMove.plan(q0, goal_from(q0), LIMITS), 0.0)
    return run_command(core, t + 0.02, lambda t, m: core.start_planned(t, m, mode, q0))


def test_enable_then_move_tracks_the_plan_and_returns_to_hold(core):
    enable(core)
    goal = np.array([0.2, 0, 0, 0, 0, 0])
    result, _ = start(core, 0.04, lambda q0: goal)
    assert result["mode"] == "move_joints" and result["duration"] > 1.0
    t, q = 0.08, np.zeros(N)
    while core.mode.name == "move_joints":
        command = core.update(measurement(t, q))
        q = command.q  # perfect tracking
        t += 0.02
    np.testing.assert_allclose(q, goal, atol=1e-9)
    assert core.mode.name == "hold" and core.state == "enabled"


def test_heartbeat_loss_stops_and_motion_needs_explicit_reset(core):
    enable(core)
    command = core.update(measurement(0.04, events=(DeviceEvent("joint3", "heartbeat_lost"),)))
    assert core.state == "stopped" and not command.enable
    assert "joint3: heartbeat lost" in core.stop_reason.message
    refused, _ = run_command(core, 0.06, core.cmd_enable)
    assert isinstance(refused, CommandRefused) and "reset first" in str(refused)
    refused, _ = start(core, 0.08, lambda q0: q0 + 0.1)
    assert isinstance(refused, CommandRefused)
    # reset is taken once the stop is over: the drives left operation (quick stop, brakes)
    assert run_command(core, 0.10, core.cmd_reset, measurement(0.10, enabled=False))[0] == "disabled"
    enable(core, 0.12)


@pytest.mark.parametrize(("kw", "code"), [
    ({"q": np.array([0, 0, 3.2, 0, 0, 0])}, "position_limit"),
    ({"dq": np.array([0, 0.5, 0, 0, 0, 0])}, "velocity_limit"),
    ({"faulted": np.array([0, 0, 0, 0, 1, 0], bool)}, "fault"),
    ({"wrench": np.array([0, 0, 200.0, 0, 0, 0])}, "ft_limit"),
    ({"wrench_overload": True}, "ft_overload"),
    ({"events": (DeviceEvent("ft_sensor", "emcy", "0x5000 hardware"),)}, "emcy"),
])
def test_each_supervised_fault_causes_protective_stop(core, kw, code):
    enable(core)
    command = core.update(measurement(0.04, **kw))
    assert core.state == "stopped" and core.stop_reason.code == code and not command.enable


def test_following_error_only_counts_while_moving(core):
    enable(core)
    core.update(measurement(0.04, q=np.full(N, 0.0)))
    # holding: a small steady offset is not a following error by itself... but a 2 deg one is
    start(core, 0.06, lambda q0: q0 + 0.5)
    for k in range(30):  # arm does not move at all: error grows past 1 deg
        core.update(measurement(0.10 + k * 0.02))
        if core.state == "stopped":
            break
    assert core.stop_reason.code == "following_error"


def test_missing_pdos_for_five_cycles_stop(core):
    enable(core)
    for k in range(4):
        core.update(measurement(0.04 + 0.02 * k, missing=("joint2",)))
    assert core.state == "enabled"
    for k in range(4, 5):
        core.update(measurement(0.04 + 0.02 * k, missing=("joint2",)))
    assert core.state == "stopped" and core.stop_reason.code == "pdo_missing"


def test_a_crashing_command_is_refused_without_killing_the_cycle(core):
    result, _ = run_command(core, 0.0, lambda t, m: 1 / 0)
    assert isinstance(result, CommandRefused) and "internal error" in str(result)
    core.update(measurement(0.02))


def test_plan_made_from_a_stale_start_is_refused(core):
    enable(core)
    q0, _ = run_command(core, 0.04, core.motion_start)
    mode = PlannedMode("move_joints", JointMove.plan(q0 + 0.01, q0 + 0.2, LIMITS), 0.0)
    refused, _ = run_command(core, 0.06, lambda t, m: core.start_planned(t, m, mode, q0 + 0.01))
    assert isinstance(refused, CommandRefused) and "moved while" in str(refused)


def test_skipped_cycles_slow_a_motion_down_instead_of_jumping_ahead(core):
    enable(core)
    start(core, 0.04, lambda q0: q0 + 0.5)
    first = core.update(measurement(0.08)).q.copy()
    # The next cycle comes 10 periods late (overrun): the target advances by one period only.
    late = core.update(measurement(0.30, q=first)).q
    assert np.max(np.abs(late - first)) <= LIMITS.v_max[0] * 0.02 * 1.01


def test_frozen_ft_count_holds_across_cycles_with_missing_data():
    """A late TPDO repeats the last values: it must neither count as 'frozen' nor restart the
    count, so a frozen sensor is stopped after ft_frozen_cycles real identical readings."""
    limits = SupervisionLimits(LIMITS.q_min, LIMITS.q_max, LIMITS.v_max)
    sup = Supervisor(limits, NAMES)
    rng = np.random.default_rng(0)
    t = 0.0
    for _ in range(limits.ft_live_changes + 5):                 # live noise arms the check
        t += 0.02
        assert not sup.check(measurement(t, wrench=rng.normal(0, 0.3, 6)), None, False)
    frozen = rng.normal(0, 0.3, 6)
    found, identical, cycle = [], 0, 0
    while not found:
        t += 0.02
        cycle += 1
        late = cycle % 5 == 0                                   # every 5th cycle: a node late
        found = [f for f in sup.check(measurement(t, wrench=frozen, missing=("joint_3",) if late else ()),
                                      None, False) if f.code == "ft_frozen"]
        identical += 0 if late else 1
        assert identical <= limits.ft_frozen_cycles + 1, "frozen count restarted by missing data"
    assert identical == limits.ft_frozen_cycles + 1             # first frozen reading is the reference
