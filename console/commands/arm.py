"""`spacearm arm import URDF --base LINK --tip LINK`: an arm file (and its bus and plant) from a URDF."""
from __future__ import annotations

import math
import os
from pathlib import Path

import typer

from spacearm.console.errors import BadInput, CommandFailed, friendly_errors
from spacearm.base.config.arm import ArmConfig, load_arm_config
from spacearm.base.kinematics.arm_import import arm_toml, import_arm
from spacearm.base.config.bus import DEFAULT_BUS_CONFIG, dump_toml
from spacearm.drivers.bus_for_arm import DriveSpec, bus_for_arm


def drive_specs(config: ArmConfig) -> list[DriveSpec]:
    """The arm file's joints as drives for the bus description."""
    return [DriveSpec(j.limits.lower, j.limits.upper, j.drive.velocity, j.drive.torque, j.drive.following_error)
            for j in config.joints]


def plant_toml(config: ArmConfig, arm_path: Path, gravity: tuple[float, float, float]) -> str:
    """A nominal plant file for the arm: joints at home, rigid-body dynamics from its [[links]]."""
    lines = [f"# Nominal simulated plant of {config.arm.name} (spacearm arm import): joints start at the",
             "# arm's home posture; coupled rigid-body dynamics from the arm file's [[links]] (Pinocchio).",
             "# Schema: firmware_sim/plant.py and firmware_sim/rigid_body.py. SI units.", "seed = 1", "",
             "[geometry]", f"arm = {arm_path.as_posix()!r}   # relative to this file", ""]
    if config.links:
        lines += ["[rigid_body]", f"gravity = [{', '.join(repr(float(g) + 0.0) for g in gravity)}]   # m/s^2, base frame",
                  ""]
    for joint in config.joints:
        lines += ["[[joints]]", f"initial_position = {joint.home!r}", ""]
    return "\n".join(lines)


def register(app: typer.Typer) -> None:
    arm_app = typer.Typer(help="Arm files: import from URDF.", no_args_is_help=True)

    @arm_app.command("import")
    @friendly_errors
    def import_(urdf: Path = typer.Argument(..., help="URDF file."),
                base: str = typer.Option(..., help="URDF link that is the arm's base frame."),
                tip: str = typer.Option(..., help="URDF link that is the arm's tool frame."),
                out: Path = typer.Option(None, help="Arm file to write (default: print it)."),
                name: str = typer.Option(None, help="Arm name (default: the URDF's file name)."),
                bus: Path = typer.Option(None, help="Also write a bus file with one drive per joint."),
                plant: Path = typer.Option(None, help="Also write a nominal plant file (needs --out)."),
                gravity: float = typer.Option(0.0, help="m/s^2 along -z of the base in the plant file "
                                                        "(0 = on orbit, 9.81 = ground test bed).")) -> None:
        """Write an arm file (modified D-H + Hayati, limits, drive limits, inertials) from a URDF chain."""
        if plant is not None and out is None:       # refused before anything is written
            raise BadInput("--plant needs --out (the plant file refers to the arm file)")
        if not math.isfinite(gravity) or abs(gravity) > 100.0:
            raise BadInput(f"--gravity {gravity}: expected 0..100 m/s^2")
        command = f"spacearm arm import {urdf} --base {base} --tip {tip}"
        data, config = import_arm(urdf, base, tip, out, name)
        text = arm_toml(data, command)
        if out is None:
            print(text, end="")
        else:
            _write(out, text)
            load_arm_config(out)   # what we wrote reads back
            print(f"{out}: {config.arm.name}, {len(config.joints)} joints "
                  f"({', '.join(j.type for j in config.joints)}), {len(config.links)} link inertials")
        if bus is not None:
            _write(bus, dump_toml(bus_for_arm(drive_specs(config), DEFAULT_BUS_CONFIG)))
            print(f"{bus}: {len(config.joints)} joint drives + the template's other devices")
        bare = [] if config.links else _without_inertial(urdf, base, tip)
        if bare:
            print(f"note: {urdf}: no <inertial> on {', '.join(bare)}: no [[links]] written, so the arm cannot run "
                  "the rigid-body plant")
        if plant is not None:
            if bare:
                raise BadInput(f"--plant: {urdf}: no <inertial> on {', '.join(bare)}; the rigid-body plant "
                               "needs one on every moving link")
            # the arm path relative to the plant file, which the loader resolves it against
            arm_path = Path(os.path.relpath(out.resolve(), plant.resolve().parent))
            _write(plant, plant_toml(config, arm_path, (0.0, 0.0, -gravity)))
            print(f"{plant}: nominal plant, gravity {gravity} m/s^2")

    app.add_typer(arm_app, name="arm")


def _without_inertial(urdf: Path, base: str, tip: str) -> list[str]:
    """The moving links (named with the joint that moves them) the URDF gives no inertial."""
    from spacearm.base.kinematics.urdf import read_chain
    chain = read_chain(urdf, base, tip)
    return [f"link {j.child!r} (joint {j.name!r})" for j, body in zip(chain.joints, chain.bodies) if body is None]


def _write(path: Path, text: str) -> None:
    try:
        path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise CommandFailed(f"{path}: cannot write: {exc.strerror}") from None
