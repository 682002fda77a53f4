"""The arm's state at a glance: the tool pose (mm, deg) and each joint's distance to its
limits in text `status` and `watch`, the last events with their codes, `kin fk ARM NAME`."""
from __future__ import annotations

import json
import math
import re
import subprocess
import sys

import numpy as np
import pytest

from spacearm.base.config.arm import load_arm_config
from spacearm.base.kinematics import load_model
from spacearm.console.status_view import event_lines, limit_margin, render_status, status_table
from spacearm.console.web.state_feed import arm_frames
from spacearm.base.kinematics.model import KinematicData
from spacearm.controller.daemon.daemon import tool_pose

ARM = "configs/arm/oru_testbed_6dof.toml"


def kin(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "spacearm.console.main", "kin", *args], capture_output=True,
                          text=True, timeout=120)


def status_at(q) -> dict:
    model = load_model(ARM)
    return {"state": "enabled", "mode": "hold", "time": 3.0, "tool": tool_pose(model, np.array(q)),
            "joints": [{"name": n, "q": v, "q_cmd": v, "dq": 0.0, "tau": 0.0, "enabled": True, "fault": False,
                        "q_min": lo, "q_max": hi} for n, v, lo, hi in zip(model.joint_names, q, model.q_min, model.q_max)],
            "events": [{"t": 1.5, "kind": "stop", "message": "no process data for 5 cycles", "code": "pdo_missing",
                        "node": "end_effector"}, {"t": 2.25, "kind": "reset", "message": "stop cleared"}]}


def test_kin_fk_takes_a_named_posture_and_matches_its_angles():
    ready = load_arm_config(ARM).postures["ready"]
    named = json.loads(kin("fk", ARM, "ready", "--json").stdout)
    typed = json.loads(kin("fk", ARM, *[repr(v) for v in ready], "--json").stdout)
    assert named["xyz"] == pytest.approx(typed["xyz"], abs=1e-12)
    assert named["rpy"] == pytest.approx(typed["rpy"], abs=1e-12)
    # The web page's frames (another caller of the kinematics) put the tool at the same place.
    model = load_model(ARM)
    tool = np.array(arm_frames(model, KinematicData(model), ready)[-1]).reshape(4, 4)
    assert tool[:3, 3] == pytest.approx(named["xyz"], abs=1e-5)
    bogus = kin("fk", ARM, "bogus")
    assert bogus.returncode == 2 and bogus.stderr.startswith("error[bad_argument]: unknown posture 'bogus'")
    assert "home, ready" in bogus.stderr and "Traceback" not in bogus.stderr


def test_text_status_shows_the_tool_pose_in_mm_and_deg_the_limits_and_the_last_events():
    ready = load_arm_config(ARM).postures["ready"]
    status = status_at(ready)
    text = render_status(status)
    xyz_mm = [1e3 * v for v in status["tool"]["xyz"]]
    line = next(x for x in text.splitlines() if x.startswith("tool (base frame)"))
    shown = [float(v) for v in re.findall(r"-?\d+\.\d+", line)]
    assert shown[:3] == pytest.approx(xyz_mm, abs=0.05)
    assert shown[3:] == pytest.approx([math.degrees(v) for v in status["tool"]["rpy"]], abs=0.005)
    # ready's joint 2 is at +90 deg of a range the arm file gives: its distance in deg, named
    j = status["joints"][1]
    distance, side = limit_margin(j)
    assert distance == pytest.approx(min(j["q"] - j["q_min"], j["q_max"] - j["q"]))
    row = next(x for x in text.splitlines() if x.startswith(j["name"]))
    assert row.endswith(f"{math.degrees(distance):8.2f} {side}")
    assert "[pdo_missing] no process data for 5 cycles (node end_effector)" in text
    assert "[reset] stop cleared" in text
    assert event_lines({"events": []}) == []


def test_a_joint_at_its_limit_reads_zero_and_watch_shows_the_same():
    model = load_model(ARM)
    q = list(model.q_home)
    q[0] = model.q_max[0]
    status = status_at(q)
    assert limit_margin(status["joints"][0]) == (pytest.approx(0.0), "max")
    from rich.console import Console
    console = Console(width=160, record=True)
    console.print(status_table(status))
    screen = console.export_text()
    assert "tool (base frame)" in screen and "to limit deg" in screen and "0.00 max" in screen
    assert "[pdo_missing]" in screen
