"""`spacearm config check FILE...`: validate configuration files, each with its own schema.

The kind of a file (arm, bus, plant, scene, campaign) is told by its top-level keys, else by
the folder it is in (configs/<kind>/), or given with --kind. A bus file is also checked
against its nodes' EDS files (every [nodes.pdo] entry: the PDO exists on the device, each
object may be mapped, the COB-IDs are free).
"""
from __future__ import annotations

import json
import sys
import tomllib
from pathlib import Path

import typer

from spacearm.base.config.errors import ConfigError
from spacearm.console.errors import friendly_errors

KINDS = ("arm", "bus", "plant", "scene", "campaign")
FOLDERS = {"arm": "arm", "bus": "bus", "plant": "plant", "scene": "scene", "campaigns": "campaign"}


def file_kind(path: Path) -> str:
    """arm, bus, plant, scene or campaign; ConfigError when the file does not say."""
    folder = FOLDERS.get(path.resolve().parent.name)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        if folder is not None:
            return folder              # its loader names what is wrong with the file
        reason = exc.strerror if isinstance(exc, OSError) else str(exc).splitlines()[0]
        raise ConfigError(f"{path}: cannot read as TOML: {reason}") from None
    for key, kind in (("campaign", "campaign"), ("arm", "arm"), ("nodes", "bus"), ("stores", "scene")):
        if key in data:
            return kind
    if folder is not None:
        return folder
    if {"joints", "joint", "geometry", "seed", "substeps"} & set(data):
        return "plant"
    raise ConfigError(f"{path}: cannot tell which kind of file this is ({', '.join(KINDS)}): "
                      f"give --kind")


def check_file(path: Path, kind: str) -> dict:
    """Validate one file with its kind's schema; a summary (ConfigError when it is wrong)."""
    if kind == "arm":
        from spacearm.base.config.arm import load_arm_config
        config = load_arm_config(path)
        return {"arm": config.arm.name, "joints": len(config.joints), "convention": config.arm.convention,
                "postures": sorted(config.postures),
                "text": f"{config.arm.name}, {len(config.joints)} joints, {config.arm.convention} D-H"}
    if kind == "bus":
        return _check_bus(path)
    if kind == "plant":
        from spacearm.firmware_sim.plant import load_plant_config
        plant = load_plant_config(path)
        return {"joints": len(plant.joints), "seed": plant.seed,
                "text": f"{len(plant.joints)} joint tables, seed {plant.seed}"}
    if kind == "scene":
        from spacearm.base.config.scene import load_scene
        scene = load_scene(path)
        return {"scene": scene.name, "stores": len(scene.stores), "orus": len(scene.orus),
                "text": f"{scene.name}, {len(scene.stores)} stores, {len(scene.orus)} ORUs"}
    from spacearm.offline.campaign.schema import load_campaign
    campaign = load_campaign(path)
    return {"campaign": campaign.spec.campaign.name, "campaign_kind": campaign.spec.campaign.kind,
            "text": f"{campaign.spec.campaign.name}, kind {campaign.spec.campaign.kind}"}


def _check_bus(path: Path) -> dict:
    from spacearm.base.canopen.eds import load_od
    from spacearm.base.config.bus import load_bus_config
    from spacearm.drivers.pdo_config import resolve_layout
    from spacearm.drivers.errors import BootError

    bus = load_bus_config(path)
    for node in bus.nodes:
        try:
            resolve_layout(node, load_od(node.eds_path, node.node_id))
        except BootError as exc:          # a MappingError names node, PDO and object
            raise ConfigError(f"{path}: {exc}") from None
    return {"nodes": len(bus.nodes), "node_ids": [n.node_id for n in bus.nodes],
            "text": f"{len(bus.nodes)} nodes (IDs {', '.join(str(n.node_id) for n in bus.nodes)}), "
                    f"every PDO layout fits its EDS"}


def register(app: typer.Typer) -> None:
    config_app = typer.Typer(help="Validate and inspect configuration files.", no_args_is_help=True)

    @config_app.command("check")
    @friendly_errors
    def check(files: list[Path] = typer.Argument(..., help="Arm, bus, plant, scene or campaign TOML files."),
              kind: str = typer.Option("", "--kind", help=f"Treat every file as this kind ({', '.join(KINDS)})."),
              as_json: bool = typer.Option(False, "--json", help="One JSON object per file.")) -> None:
        """Validate each file with its own schema; print a one-line summary each or its error."""
        if kind and kind not in KINDS:
            raise ConfigError(f"--kind {kind}: one of {', '.join(KINDS)}")
        errors: list[ConfigError] = []
        for path in files:
            try:
                file_type = kind or file_kind(path)
                summary = check_file(path, file_type)
            except ConfigError as exc:
                errors.append(exc)
                continue
            text = summary.pop("text")
            print(json.dumps({"file": str(path), "ok": True, "kind": file_type, **summary}) if as_json
                  else f"{path}: ok ({file_type}: {text})")
        for exc in errors[:-1]:          # one line each; the last one ends the command (exit 2)
            print(json.dumps({"ok": False, "error": str(exc), "code": "bad_config"}) if as_json
                  else f"error[bad_config]: {exc}", file=sys.stderr)
        if errors:
            raise errors[-1]

    app.add_typer(config_app, name="config")
