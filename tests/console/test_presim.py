"""The browser console's presimulation names the check a refused command failed, from the
planner's own failure kind (not from the words of its message)."""
import pytest

from spacearm.base.kinematics.model import load_model
from spacearm.base.paths import CONFIGS
from spacearm.console.web.presim import Presimulator

READY = [-0.28806419791259463, 1.5707963267948966, -3.294079780986511, 1.9521648103310305,
         -0.22888135613941607, 1.2827321288823015]


@pytest.fixture(scope="module")
def presim():
    return Presimulator(load_model(CONFIGS / "arm/oru_testbed_6dof.toml"), 0.02)


def status_at(q):
    return {"state": "enabled", "mode": None, "joints": [{"q_cmd": v} for v in q]}


def failed_check(result):
    return next(c.name for c in result.checks if not c.ok)


def test_a_jog_past_the_limit_fails_the_joint_limit_check(presim):
    result = presim.run("jog", {"joint": 1, "delta": 1.5}, status_at([2.0, 0, 0, 0, 0, 0]))
    assert not result.accepted and failed_check(result) == "joint limits"


def test_a_pose_beyond_reach_fails_the_reachability_check(presim):
    result = presim.run("move_pose", {"xyz": [5.0, 0.0, 0.0], "rpy": [0.0, 0.0, 0.0]}, status_at(READY))
    assert not result.accepted and failed_check(result) == "reachability"
    assert "reach" in result.reason


def test_a_small_tool_move_from_ready_passes_every_check(presim):
    result = presim.run("move_pose", {"xyz": [0.0, 0.0, 0.02], "rpy": [0.0, 0.0, 0.0], "frame": "tool"},
                        status_at(READY))
    assert result.accepted, result.reason
    assert {c.name for c in result.checks} >= {"arguments", "joint limits", "reachability", "arm state"}
