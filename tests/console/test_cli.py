"""The `spacearm` command: every subcommand documents itself; kinematics at the console."""
from __future__ import annotations

import json

import pytest
import typer
from typer.testing import CliRunner

from spacearm.console.main import app

ORU = "configs/arm/oru_testbed_6dof.toml"
runner = CliRunner()


def all_command_paths() -> list[list[str]]:
    root = typer.main.get_command(app)
    paths = []

    def walk(command, path: list[str]) -> None:
        paths.append(path)
        if hasattr(command, "commands"):  # a group (typer vendors its own click)
            for name, sub in command.commands.items():
                walk(sub, path + [name])

    walk(root, [])
    return paths


def test_top_level_help_lists_the_subcommands():
    result = runner.invoke(app, ["--help"])
    assert result.exit_code == 0
    for name in ("config", "kin", "status", "move", "stop", "reset", "export"):
        assert name in result.output


@pytest.mark.parametrize("path", all_command_paths(), ids=lambda p: " ".join(p) or "spacearm")
def test_every_subcommand_has_help(path):
    result = runner.invoke(app, path + ["--help"])
    assert result.exit_code == 0, result.output
    assert "Usage:" in result.output


def test_fk_at_home_matches_the_hand_computed_pose():
    result = runner.invoke(app, ["kin", "fk", ORU, "--json"])
    assert result.exit_code == 0
    pose = json.loads(result.output)
    assert pose["xyz"] == pytest.approx([0.174, 1.590, 0.0], abs=1e-9)


def test_ik_accepts_units_and_negative_numbers_and_round_trips():
    result = runner.invoke(app, ["kin", "ik", ORU, "300mm", "400mm", "-0.0", "180deg", "0", "0",
                                 "--seed", "ready", "--json"])
    assert result.exit_code == 0, result.output
    q = json.loads(result.output)["q"]
    back = json.loads(runner.invoke(app, ["kin", "fk", ORU, *map(str, q), "--json"]).output)
    assert back["xyz"] == pytest.approx([0.3, 0.4, 0.0], abs=1e-9)


@pytest.mark.parametrize(("args", "message"), [
    (["kin", "fk", ORU, "1", "2"], "has 6 joints, got 2 angles"),
    (["kin", "fk", ORU, "1", "2", "3", "4", "5", "6furlongs"], "unknown angle unit 'furlongs'"),
    (["kin", "ik", ORU, "4", "3", "2", "0", "0", "0"], "no solution"),
    (["kin", "fk", "configs/arm/nope.toml"], "file not found"),
    (["status", "--api", "tcp:127.0.0.1:1"], "cannot reach the daemon"),
])
def test_bad_input_gives_one_line_and_nonzero_exit(args, message):
    result = runner.invoke(app, args)
    assert result.exit_code != 0
    assert message in result.output
    assert "Traceback" not in result.output


@pytest.mark.parametrize(("args", "message"), [
    (["oru", "run", "--stages", "one", "--api", "tcp:127.0.0.1:1"], "--stages: expected stage numbers"),
    (["demo", "--job", "nope"], "--job: expected changeout or checkout"),
    (["demo", "--stages", "1;2"], "--stages: expected numbers"),
    (["arm", "import", "x.urdf", "--base", "b", "--tip", "t", "--plant", "p.toml"], "--plant needs --out"),
    (["arm", "import", "x.urdf", "--base", "b", "--tip", "t", "--gravity", "981"], "--gravity 981.0: expected"),
])
def test_a_bad_option_value_is_bad_input_with_its_code(args, message):
    """Exit 2 and `error[bad_input]` like every other typo (exit 1 is for refused commands),
    before any connection or set-up is attempted."""
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    assert f"error[bad_input]: {message}" in result.output
    assert "Traceback" not in result.output
