"""`spacearm sim` command."""
from __future__ import annotations

import typer
from typer.testing import CliRunner

from spacearm.console.commands.sim import register


def app() -> typer.Typer:
    a = typer.Typer()
    register(a)

    @a.command("other")
    def other() -> None:   # a second command so typer keeps "sim" as a subcommand
        pass
    return a


def test_sim_runs_and_reports_ready():
    result = CliRunner().invoke(app(), ["sim", "--bus", "virtual:cli-test", "--duration", "0.2", "--stats",
                                        "--plant", "firmware_sim/plants/realistic.toml"])
    assert result.exit_code == 0, result.output
    assert "spacearm sim: 8 nodes ready on virtual:cli-test" in result.output
    assert "internal_errors=0" in result.output


def test_sim_bad_bus_spec_and_bad_config_are_one_line_errors(tmp_path):
    result = CliRunner().invoke(app(), ["sim", "--bus", "nonsense", "--duration", "0.1"])
    assert result.exit_code == 2 and "expected KIND:NAME" in result.output
    bad = tmp_path / "bus.toml"
    bad.write_text('[[nodes]]\nname = "j"\nnode_id = 300\ndevice = "joint_drive"\n')
    result = CliRunner().invoke(app(), ["sim", "--bus", "virtual:x", "--bus-config", str(bad), "--duration", "0.1"])
    assert result.exit_code == 2 and "nodes #1.node_id" in result.output and "Traceback" not in result.output


def test_sim_with_a_missing_eds_is_a_one_line_error(tmp_path):
    bus = tmp_path / "bus.toml"
    bus.write_text('[[nodes]]\nname = "j"\nnode_id = 3\ndevice = "joint_drive"\neds = "nothere.eds"\n')
    result = CliRunner().invoke(app(), ["sim", "--bus", "virtual:x", "--bus-config", str(bus), "--duration", "0.1"])
    assert result.exit_code == 2 and "nothere.eds: cannot read" in result.output
    assert "Traceback" not in result.output
