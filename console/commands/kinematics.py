"""`spacearm kin fk|ik`: forward and inverse kinematics of an arm file, for operators."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import typer

from spacearm.console.errors import BadInput, CommandFailed, friendly_errors
from spacearm.console.units import UnitError, parse_angle, parse_length
from spacearm.base.kinematics import (KinematicData, analytic_ik, fk, load_model, matrix_to_rpy,
                                   rpy_to_matrix, solve_ik)

ARM_ARGUMENT = typer.Argument(..., help="Arm file, e.g. configs/arm/oru_testbed_6dof.toml.")


def _pose_text(T: np.ndarray) -> str:
    x, y, z = T[:3, 3] * 1e3
    r, p, w = np.degrees(matrix_to_rpy(T[:3, :3]))
    return f"x {x:.3f} mm  y {y:.3f} mm  z {z:.3f} mm  roll {r:.4f} deg  pitch {p:.4f} deg  yaw {w:.4f} deg"


# Let negative numbers through as arguments (click would read "-0.5" as an option).
NUMERIC_ARGS = {"ignore_unknown_options": True}


def _joints_text(model, q, column: str = "10.4f", unit: str = "  deg") -> str:
    """Joint values for people: revolute joints in deg, prismatic joints in mm."""
    if "prismatic" not in model.joint_types:
        return " ".join(f"{math.degrees(v):{column}}" for v in q) + unit
    return " ".join(f"{v * 1e3:.3f}mm" if kind == "prismatic" else f"{math.degrees(v):.4f}deg"
                    for v, kind in zip(q, model.joint_types))


def _posture(arm: Path, model, name: str) -> list[float]:
    """A named posture of the arm file (its [postures], and home), in rad/m."""
    from spacearm.base.config.arm import load_arm_config
    postures = load_arm_config(arm).postures
    if name == "home" and name not in postures:
        return list(model.q_home)
    if name not in postures:
        raise BadInput(f"unknown posture {name!r}; the arm file has: {', '.join(dict.fromkeys(['home', *postures]))}",
                       "bad_argument")
    return list(postures[name])


def register(app: typer.Typer) -> None:
    kin_app = typer.Typer(help="Forward and inverse kinematics of an arm file.", no_args_is_help=True)

    @kin_app.command("fk", context_settings=NUMERIC_ARGS)
    @friendly_errors
    def forward(arm: Path = ARM_ARGUMENT,
                q: list[str] = typer.Argument(None, help="Joint angles (rad, or with deg), or a named posture "
                                              "of the arm file (home, ready, ...); default: home."),
                as_json: bool = typer.Option(False, "--json")) -> None:
        """Tool pose in the base frame for joint angles Q or a named posture."""
        model = load_model(arm)
        if q and len(q) == 1 and q[0][:1].isalpha():
            q = [repr(v) for v in _posture(arm, model, q[0])]
        try:
            # a prismatic joint takes a length (m, or with mm)
            angles = (np.array([parse_length(v) if kind == "prismatic" else parse_angle(v)
                                for v, kind in zip(q, model.joint_types + ("revolute",) * len(q))])
                      if q else np.array(model.q_home))
        except UnitError as exc:
            raise CommandFailed(str(exc)) from None
        if len(angles) != model.nq:
            raise CommandFailed(f"{model.name} has {model.nq} joints, got {len(angles)} angles")
        T = fk(model, KinematicData(model), angles)
        if as_json:
            print(json.dumps({"xyz": T[:3, 3].tolist(), "rpy": matrix_to_rpy(T[:3, :3]).tolist(),
                              "matrix": T.tolist()}))
        else:
            print(_pose_text(T))

    @kin_app.command("ik", context_settings=NUMERIC_ARGS)
    @friendly_errors
    def inverse(arm: Path = ARM_ARGUMENT,
                pose: list[str] = typer.Argument(..., help="x y z roll pitch yaw (m/rad, or mm/deg)."),
                seed: str = typer.Option("home", help="Seed posture: a posture name of the arm file."),
                all_solutions: bool = typer.Option(False, "--all", help="List every closed-form solution."),
                as_json: bool = typer.Option(False, "--json")) -> None:
        """Joint angles that put the tool at POSE (nearest to the seed posture)."""
        if len(pose) != 6:
            raise CommandFailed(f"pose needs 6 values (x y z roll pitch yaw), got {len(pose)}")
        try:
            xyz = [parse_length(v) for v in pose[:3]]
            rpy = [parse_angle(v) for v in pose[3:]]
        except UnitError as exc:
            raise CommandFailed(str(exc)) from None
        model = load_model(arm)
        q0 = np.array(_posture(arm, model, seed))
        T = np.eye(4)
        T[:3, :3] = rpy_to_matrix(rpy)
        T[:3, 3] = xyz
        if all_solutions:
            solutions = analytic_ik(model, T, q_hint=q0)
            if not solutions:
                raise CommandFailed("no closed-form solution within the joint limits")
            result = [s.tolist() for s in solutions]
            print(json.dumps(result) if as_json else
                  "\n".join(_joints_text(model, s) for s in solutions))
            return
        found = solve_ik(model, KinematicData(model), T, q0)
        if not found.success:
            raise CommandFailed(f"no solution: {found.message}")
        if as_json:
            print(json.dumps({"q": found.q.tolist(), "pos_error": found.pos_error, "rot_error": found.rot_error}))
        else:
            print(_joints_text(model, found.q, ".4f", " deg") +
                  f"  (error {found.pos_error * 1e3:.2e} mm, {math.degrees(found.rot_error):.2e} deg)")

    app.add_typer(kin_app, name="kin")
