"""`spacearm calibrate ...`: kinematic identification studies, fits of data files, FR3 real data."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import typer

from console.errors import CommandFailed, friendly_errors

STUDIES = ("laser-ranger", "ekf")


def _fmt_value(name: str, value: float) -> str:
    kind = name.rsplit("_", 1)[0] if not name.startswith(("plane_",)) else "plane"
    if kind in ("d", "a") or name.endswith(("_x", "_y", "_z")):
        return f"{value * 1e3:+.4f} mm"
    if kind == "plane":
        return f"{value:+.6f}"
    return f"{value * 1e3:+.4f} mrad"


def register(app: typer.Typer) -> None:
    cal = typer.Typer(help="Kinematic calibration: paper studies, data fits, real FR3 data.",
                      no_args_is_help=True)

    @cal.command("study")
    @friendly_errors
    def study(which: str = typer.Argument(..., help="laser-ranger | ekf"),
              runs: int = typer.Option(0, help="Monte-Carlo runs (default 20 laser, 10 ekf)."),
              seed: int = typer.Option(0, help="First seed."),
              out: Path = typer.Option(Path("calibration_plots"), help="Folder for PNG plots (ekf)."),
              as_json: bool = typer.Option(False, "--json", help="Also print the headline numbers as JSON.")) -> None:
        """Reproduce a paper's simulation study and print our tables beside the paper's."""
        from controller.calibration.studies import ekf_study, laser_study
        if which not in STUDIES:
            raise CommandFailed(f"unknown study {which!r}; choose one of {', '.join(STUDIES)}")
        if which == "laser-ranger":
            text, head = laser_study(runs=runs or 20, seed0=seed)
        else:
            text, head = ekf_study(runs=runs or 10, seed0=seed, out_dir=out)
        print(text)
        if as_json:
            print(json.dumps(head, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))

    @cal.command("fit")
    @friendly_errors
    def fit(data: Path = typer.Option(..., "--data", help="CSV: q1..qn + T_00..T_23 | x,y,z | h."),
            model: Path = typer.Option(..., "--model", help="Arm file, e.g. configs/arm/ssrms_7dof.toml."),
            method: str = typer.Option("lm", help="lm | lse | ekf"),
            sigma_pos: float = typer.Option(0.3e-3, help="Position / distance noise, m."),
            sigma_rot: float = typer.Option(np.radians(0.5), help="Orientation noise, rad."),
            plane: str = typer.Option("", help="Plane 'nx,ny,nz,f' for distance data (n.p + f = 0)."),
            gauge: str = typer.Option("plane_ny", help="Plane coefficient held fixed (scale)."),
            frames: bool = typer.Option(False, help="Also consider base/tool frame parameters."),
            as_json: bool = typer.Option(False, "--json")) -> None:
        """Identify the identifiable parameters of MODEL from a measurement file."""
        from controller.calibration.datafile import DataFileError, read_measurements
        from controller.calibration.errormodel import ErrorModel
        from controller.calibration.identifiability import find_identifiable
        from controller.calibration.residuals import PlaneTarget, Problem
        from controller.calibration.solvers import EKFTuning, ekf, lm, lse
        from controller.kinematics import load_model
        kin = load_model(model)
        try:
            mf = read_measurements(data, kin.nq)
        except DataFileError as exc:
            raise CommandFailed(str(exc)) from None
        em = ErrorModel.from_kinematics(kin)
        pt = None
        if mf.kind == "plane":
            try:
                vals = [float(v) for v in plane.split(",")]
            except ValueError:
                vals = []
            if len(vals) != 4:
                raise CommandFailed("distance data needs --plane 'nx,ny,nz,f'")
            pt = PlaneTarget(tuple(vals[:3]), vals[3])
        cands = [n for n in em.names if frames or not n.startswith((em.world_prefix + "_", em.tool_prefix + "_"))]
        cands += pt.names if pt else []
        if len(mf.Q) < 2:
            raise CommandFailed("need at least two postures")
        sig = {"pose": [sigma_pos] * 3 + [sigma_rot] * 3, "position": [sigma_pos] * 3,
               "plane": [sigma_pos]}[mf.kind]
        probe = Problem(em, mf.kind, mf.Q, mf.measured, cands, plane=pt, sigma=np.array(sig))
        rep = find_identifiable(probe, cands, gauge=gauge if pt else None)
        pr = Problem(em, mf.kind, mf.Q, mf.measured, rep.kept, plane=pt, sigma=np.array(sig))
        if pr.rows * pr.n_configs < len(rep.kept):
            raise CommandFailed(f"{pr.rows * pr.n_configs} equations for {len(rep.kept)} parameters")
        if method == "lm":
            res = lm(pr)
        elif method == "lse":
            res = lse(pr)
        elif method == "ekf":
            res = ekf(pr, EKFTuning.paper(pr), passes=3)
        else:
            raise CommandFailed(f"unknown method {method!r} (lm, lse, ekf)")
        if as_json:
            print(json.dumps({"method": res.method, "status": res.status, "iterations": res.iterations,
                              "estimate": res.estimate, "std": res.std, "rms_residual": res.rms_residual,
                              "dropped": {d.name: d.reason for d in rep.dropped}}))
            return
        print(rep.summary())
        print(f"\n{res.method}: {res.status} ({res.message}), {res.iterations} iterations, "
              f"{res.elapsed * 1e3:.1f} ms, RMS residual {res.rms_residual:.3e}")
        for name, value in res.estimate.items():
            print(f"  {name:<12} {_fmt_value(name, value):>18}  +- {_fmt_value(name, res.std[name])}")

    @cal.command("fr3")
    @friendly_errors
    def fr3(splits: int = typer.Option(10, help="Random 80/34 splits."),
            seed: int = typer.Option(0),
            data: Path = typer.Option(None, help="samples.csv (default ../shared/data/fr3_eye_in_hand).")) -> None:
        """Fit the real FR3 eye-in-hand data; held-out error, registration-only vs full."""
        from controller.calibration.fr3 import DATA, fr3_study
        path = data or DATA
        if not Path(path).exists():
            raise CommandFailed(f"FR3 data not found: {path}")
        text, _ = fr3_study(splits=splits, seed=seed, path=path)
        print(text)

    app.add_typer(cal, name="calibrate")
