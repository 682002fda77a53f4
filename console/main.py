"""Entry point of the `spacearm` command: a typer app with one subcommand group per module."""
from __future__ import annotations

import importlib

import typer

app = typer.Typer(
    name="spacearm",
    help="Hardware-in-the-loop controller stack for a space-station manipulator (CANopen).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

# Subcommand modules; each defines register(app). Optional ones may be absent while
# their issue is in progress, so a missing module is skipped rather than breaking the CLI.
COMMAND_MODULES = ("config", "kinematics", "demo", "daemon", "operate", "export", "calibrate", "sim", "hub",
                   "record_sim", "diagnose", "web", "oru", "approach", "arm", "campaign")

for module_name in COMMAND_MODULES:
    try:
        module = importlib.import_module(f"spacearm.console.commands.{module_name}")
    except ModuleNotFoundError as exc:
        if exc.name != f"spacearm.console.commands.{module_name}":
            raise
        continue
    module.register(app)


if __name__ == "__main__":
    app()
