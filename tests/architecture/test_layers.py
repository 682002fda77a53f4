"""Imports run one way (spacearm/architecture.py), and the distribution installs one package."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from spacearm.architecture import REPO_ROOT, check_source, import_graph, violations


def test_the_tree_has_no_wrong_way_import():
    found = violations()
    assert not found, "\n".join(map(str, found))


def test_the_graph_has_the_rooms_and_their_edges():
    graph = import_graph()
    assert ("controller.daemon", "drivers") in graph
    assert ("offline", "firmware_sim") in graph
    assert not any(src in ("drivers", "firmware_sim") and dst.startswith("controller") for src, dst in graph)


@pytest.mark.parametrize("path, snippet, why", [
    ("drivers/network.py", "from spacearm.controller.daemon.core import ControllerCore", "a room above it"),
    ("drivers/network.py", "from spacearm.firmware_sim.node import SimNode", "independent rooms"),
    ("firmware_sim/plant.py", "import spacearm.drivers.network", "independent rooms"),
    ("base/kinematics/model.py", "from spacearm.drivers.errors import DriverError", "a room above it"),
    ("controller/oru/flow.py", "from spacearm.controller.daemon.core import CommandRefused", "a room above it"),
    ("controller/cycle.py", "from spacearm.controller.modes import HoldMode", "a room above it"),
    ("controller/planning/joint_move.py", "from spacearm.controller.vision.pnp import solve_pnp", "independent rooms"),
    ("controller/daemon/daemon.py", "from spacearm.offline.diagnosis.analysis import diagnose", "a room above it"),
    ("offline/diagnosis/analysis.py", "from spacearm.console.main import app", "a room above it"),
    ("controller/daemon/core.py", "from controller.cycle import Finding", "bare `controller` import"),
    ("tests/daemon/test_core.py", "import drivers.network", "bare `drivers` import"),
    # an import hidden in a function body counts the same
    ("drivers/devices.py", "def f():\n    from spacearm.controller.cycle import Finding\n", "a room above it"),
])
def test_a_wrong_way_import_is_reported(path, snippet, why):
    found = check_source(path, textwrap.dedent(snippet))
    assert len(found) == 1 and why in found[0].why, found


@pytest.mark.parametrize("path, snippet", [
    ("controller/daemon/daemon.py", "from spacearm.controller.oru.runner import OruTaskRunner"),
    ("controller/oru/flow.py", "from spacearm.controller.cycle import Mode"),
    ("offline/contact/trials.py", "from spacearm.firmware_sim.plant import Plant"),
    ("console/commands/sim.py", "from spacearm.offline.diagnosis.analysis import diagnose"),
    ("firmware_sim/plant.py", "from spacearm.base.kinematics.model import KinematicModel"),
    ("tests/daemon/test_core.py", "from spacearm.controller.daemon.core import ControllerCore"),
])
def test_a_right_way_import_passes(path, snippet):
    assert check_source(path, snippet) == []


def test_the_command_prints_the_graph_and_exits_zero():
    out = subprocess.run([sys.executable, "-m", "spacearm.architecture"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "controller.daemon -> " in out.stdout and "violations: 0" in out.stdout


@pytest.mark.slow
def test_the_built_distribution_holds_one_top_level_package(tmp_path):
    """`pip install .` puts spacearm/<room>/... in site-packages and no `drivers`, `controller`, ..."""
    source, target = tmp_path / "src", tmp_path / "site"
    source.mkdir()
    for name in ("pyproject.toml", "setup.py", "README.md"):   # a copy: setuptools builds in the tree
        shutil.copy(REPO_ROOT / name, source / name)
    for room in ("spacearm", "base", "drivers", "firmware_sim", "controller", "offline", "console"):
        shutil.copytree(REPO_ROOT / room, source / room, ignore=shutil.ignore_patterns("__pycache__"))
    build = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", str(target),
                            str(source)], capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stderr[-2000:]
    top = sorted(p.name for p in target.iterdir() if p.is_dir() and p.name != "bin" and not p.name.endswith((".dist-info", "__pycache__")))
    assert top == ["spacearm"], top
    for room in ("base", "drivers", "firmware_sim", "controller", "offline", "console"):
        assert (target / "spacearm" / room / "__init__.py").is_file(), room
    assert (target / "spacearm" / "console" / "web" / "static").is_dir()
    # imported from the installed copy, from a directory that is not the clone
    env = dict(os.environ, PYTHONPATH=str(target))
    probe = ("import importlib.util, spacearm.drivers.network as n; "
             "print(n.__file__); print(importlib.util.find_spec('drivers'))")
    run = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=tmp_path, env=env,
                         timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    located, bare = run.stdout.split()
    assert Path(located).is_relative_to(target) and bare == "None"
