"""`spacearm config check FILE...`: validate configuration files."""
from __future__ import annotations

import json
from pathlib import Path

import typer

from spacearm.console.errors import friendly_errors
from spacearm.base.config.arm import load_arm_config


def register(app: typer.Typer) -> None:
    config_app = typer.Typer(help="Validate and inspect configuration files.", no_args_is_help=True)

    @config_app.command("check")
    @friendly_errors
    def check(files: list[Path] = typer.Argument(..., help="Arm TOML files (configs/arm/*.toml)."),
              as_json: bool = typer.Option(False, "--json", help="One JSON object per file.")) -> None:
        """Validate arm files; print a one-line summary each or the first error."""
        for path in files:
            config = load_arm_config(path)
            if as_json:
                print(json.dumps({"file": str(path), "ok": True, "arm": config.arm.name,
                                  "joints": len(config.joints), "convention": config.arm.convention,
                                  "postures": sorted(config.postures)}))
            else:
                print(f"{path}: ok ({config.arm.name}, {len(config.joints)} joints, "
                      f"{config.arm.convention} D-H)")

    app.add_typer(config_app, name="config")
