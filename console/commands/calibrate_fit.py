"""`spacearm calibrate fit` and `calibrate next`: offline fits of measurement files (any mix of
pose, 3-D point, range and plane data) with validation and a plausibility verdict, and the
postures to measure next."""
from __future__ import annotations

import json
from pathlib import Path
from typing import List, Optional

import numpy as np
import typer

from spacearm.console.errors import BadInput, CommandFailed, friendly_errors

GROUP_HELP = "joint_angle, joint_length, frame_length, frame_angle, plane"


def _fmt(name: str, value: float) -> str:
    from spacearm.controller.calibration.fit_checks import format_value
    return format_value(name, value, "mrad")


def _groups(text: str, what: str, cls, prefixes: bool = False):
    """'joint_angle=0.01,frame_length=0.05' -> cls(joint_angle=0.01, frame_length=0.05); with
    `prefixes`, other keys are parameter-name prefixes ('wire_a=0.002' -> by_prefix)."""
    if not text:
        return cls()
    values, by_prefix = {}, []
    for item in text.split(","):
        key, _, val = (part.strip() for part in item.partition("="))
        try:
            value = float(val)
        except ValueError:
            raise BadInput(f"{what}: {item!r} is not GROUP=VALUE (groups: {GROUP_HELP})") from None
        if not (value > 0 and np.isfinite(value)):
            raise BadInput(f"{what}: {item!r} must be positive and finite")
        if key in cls.__dataclass_fields__ and key != "by_prefix":
            values[key] = value
        elif prefixes and key:
            by_prefix.append((key, value))
        else:
            raise BadInput(f"{what}: unknown group {key!r} (groups: {GROUP_HELP})")
    return cls(**values, by_prefix=tuple(by_prefix)) if prefixes else cls(**values)


def _setup(data: List[Path], model: Path, sigma_pos: float, sigma_rot: float, plane: str, anchor: str,
           tool_point: str, register: bool, frames: bool, fix: str, validate: List[Path] = (),
           elasticity: bool = False):
    """Kinematics, blocks, error model, candidate parameters and validation blocks (another
    session's files, same instruments) from the command line; `elasticity`: a compliance per
    joint under the gravity load of the arm file's links among the candidates."""
    from spacearm.controller.calibration.composite import CompositeProblem
    from spacearm.controller.calibration.errormodel import ErrorModel
    from spacearm.controller.calibration.fit_setup import (Instruments, SetupError, initial_registration, load_blocks,
                                                  parse_vector)
    from spacearm.base.kinematics import load_model
    kin = load_model(model)
    try:
        inst = Instruments(sigma_pos, sigma_rot, parse_vector(plane, (4,), "--plane"),
                           parse_vector(anchor, (3, 4), "--anchor"),
                           parse_vector(tool_point, (3,), "--tool-point") or (0.0, 0.0, 0.0))
        blocks = load_blocks(data, kin, inst)
        vblocks = load_blocks(list(validate), kin, inst) if validate else []
        load = _joint_load(model, kin) if elasticity else None
        em = ErrorModel.from_kinematics(kin, load=load)
        if register:
            em = ErrorModel.from_kinematics(kin, world=initial_registration(em, blocks), load=load)
    except SetupError as exc:
        raise BadInput(str(exc)) from None
    names = CompositeProblem(em, blocks, []).names
    fixed = [p.strip() for p in fix.split(",") if p.strip()]
    frame_names = em.frame_names("world") + em.frame_names("tool")
    cands = [n for n in names if (frames or register or n not in frame_names)
             and not any(n == f or n.startswith(f) for f in fixed)]
    return kin, em, blocks, cands, vblocks


def _joint_load(model: Path, kin):
    """Gravity load per joint from the arm file's [[links]] (mass, centre of mass per link)."""
    from spacearm.base.config.arm import load_arm_config
    from spacearm.controller.calibration.joint_load import JointLoad
    links = load_arm_config(model).links
    if not links or all(ln.mass == 0.0 for ln in links):
        raise BadInput(f"--elasticity: {model} has no link masses ([[links]] mass, com), so no gravity load "
                       f"to deflect the joints; `spacearm arm import` writes them from a URDF")
    try:
        return JointLoad.from_config(kin, links)
    except ValueError as exc:
        raise BadInput(f"--elasticity: {model}: {exc}") from None


def register_fit(cal: typer.Typer) -> None:
    @cal.command("fit")
    @friendly_errors
    def fit(data: List[Path] = typer.Option(..., "--data", help="CSV per instrument: q1..qn + T_00..T_23 | x,y,z "
                                            "| range | h (repeat --data to combine)."),
            model: Path = typer.Option(..., "--model", help="Arm file, e.g. configs/arm/ssrms_7dof.toml."),
            method: str = typer.Option("lm", help="lm | lse | ekf | ekf-paper"),
            sigma_pos: float = typer.Option(0.3e-3, help="Position / distance noise (1 sigma), m."),
            sigma_rot: float = typer.Option(np.radians(0.5), help="Orientation noise of pose data, rad."),
            plane: str = typer.Option("", help="Plane 'nx,ny,nz,f' for distance data (n.p + f = 0)."),
            anchor: str = typer.Option("", help="Approximate anchor 'ax,ay,az[,l0]' (m) for range data."),
            tool_point: str = typer.Option("", help="Approximate measured point on the tool 'x,y,z' (m, tool frame)."),
            frames: bool = typer.Option(False, help="Also estimate the base and tool frame corrections."),
            register: bool = typer.Option(False, help="Data are in an external frame (mocap, tracker): "
                                          "register it to the base (initial guess by Kabsch, then estimated)."),
            fix: str = typer.Option("", help="Parameters or prefixes held fixed, e.g. 'wire_a,plane_'."),
            prior: str = typer.Option("", help=f"Regularisation: prior sigma per group or name prefix "
                                      f"'GROUP=SI,wire_a=0.002,...' ({GROUP_HELP})."),
            bound: str = typer.Option("", help="Plausibility bounds per group 'GROUP=SI,...' (defaults: 5 deg, 50 mm, "
                                      "100 mm, 10 deg, 0.5)."),
            holdout: float = typer.Option(0.2, min=0.0, max=0.8, help="Fraction of postures held out."),
            kfold: int = typer.Option(0, min=0, max=50, help="k-fold cross-validation instead (k > 1)."),
            noise: str = typer.Option("residual", help="Uncertainties: residual (scaled by the fit) | stated."),
            max_noise_ratio: float = typer.Option(3.0, help="Reject when residual RMS exceeds this x the stated noise."),
            seed: int = typer.Option(0),
            validate: List[Path] = typer.Option([], "--validate", help="Another session's measurement file(s), "
                                                "same instruments: every --data posture fits, these score it."),
            regularise: str = typer.Option("auto", help="auto: a prior of 0.5 deg / 5 mm on the D-H terms where the "
                                           "problem is weakly conditioned (the effect on held-out error is printed) | off."),
            select_groups: bool = typer.Option(False, "--select-groups", help="Drop D-H groups (alpha_i, a_i, ...) "
                                               "whose removal lowers the leave-one-out error on the training postures "
                                               "(few postures per parameter; the held-out figure stays honest)."),
            elasticity: bool = typer.Option(False, "--elasticity", help="Also a compliance per joint under its "
                                            "gravity load (the arm file's link masses), k_1..k_n in rad/(N m) or "
                                            "m/N, each bounded by a 5 deg / 50 mm deflection; with --select-groups "
                                            "each is kept or dropped on its own."),
            apply: Optional[Path] = typer.Option(None, "--apply", help="Write the calibrated arm file here."),
            as_json: bool = typer.Option(False, "--json")) -> None:
        """Identify, validate on held-out postures and judge a calibration from measurement files."""
        from spacearm.controller.calibration.fit_checks import Bounds, Priors
        from spacearm.controller.calibration.trusted_fit import FitInputError, FitOptions, fit_blocks
        try:
            opts = FitOptions(method=method, holdout=holdout, kfold=kfold, seed=seed,
                              priors=_groups(prior, "--prior", Priors, prefixes=True),
                              bounds=_groups(bound, "--bound", Bounds), noise=noise, max_noise_ratio=max_noise_ratio,
                              regularise=regularise, select_groups=select_groups)
        except FitInputError as exc:
            raise BadInput(str(exc)) from None
        kin, em, blocks, cands, vblocks = _setup(data, model, sigma_pos, sigma_rot, plane, anchor, tool_point,
                                                 register, frames, fix, validate, elasticity)
        try:
            rep = fit_blocks(em, blocks, opts, candidates=cands, validation=vblocks or None)
        except FitInputError as exc:            # too few postures for what is identifiable
            raise BadInput(str(exc)) from None
        except (ValueError, np.linalg.LinAlgError) as exc:     # the numerics failed: a failed fit
            raise CommandFailed(str(exc)) from None
        res, ident = rep.result, rep.identifiability
        if as_json:
            print(json.dumps({
                "method": res.method, "status": res.status, "iterations": res.iterations, "ok": rep.verdict.ok,
                "reasons": rep.verdict.reasons, "estimate": res.estimate, "std": rep.std,
                "noise_ratio": rep.noise_ratio, "rank": ident.rank, "condition": ident.condition,
                "dropped": {d.name: d.reason for d in ident.dropped},
                "held_out_rms_before": rep.held_rms("before"), "held_out_rms_after": rep.held_rms("after"),
                "validation_file": rep.validation_file, "regularised": rep.regularised,
                "instrument": {n: float(res.x[i]) for i, n in enumerate(res.names) if i >= em.n_params},
                "held_out_rms_unregularised": rep.held_unregularised,
                "dropped_groups": list(rep.selection.dropped) if rep.selection else None,
                "held_out": [h.__dict__ for h in rep.held_out]}))
        else:
            _print_report(rep, opts)
        if not rep.verdict.ok:
            raise CommandFailed(rep.verdict.message() + ("; nothing written" if apply else ""))
        if apply is not None:
            from spacearm.controller.calibration.calibrated_arm import apply as write_arm
            from spacearm.controller.calibration.laser_routine import CalibrationRunError
            try:
                write_arm(model, apply, em, rep, [str(d) for d in data], method)
            except (CalibrationRunError, ValueError) as exc:
                raise CommandFailed(str(exc)) from None
            if not as_json:
                print(f"calibrated arm file written: {apply}")

    @cal.command("next")
    @friendly_errors
    def next_cmd(data: List[Path] = typer.Option(..., "--data", help="Measurement files taken so far."),
                 model: Path = typer.Option(..., "--model", help="Arm file."),
                 candidates: int = typer.Option(500, min=10, max=100000, help="Random candidate postures within limits."),
                 count: int = typer.Option(10, min=1, max=1000, help="Postures to propose."),
                 sigma_pos: float = typer.Option(0.3e-3, help="Position / distance noise (1 sigma), m."),
                 sigma_rot: float = typer.Option(np.radians(0.5), help="Orientation noise of pose data, rad."),
                 plane: str = typer.Option(""), anchor: str = typer.Option(""), tool_point: str = typer.Option(""),
                 frames: bool = typer.Option(False), register: bool = typer.Option(False),
                 fix: str = typer.Option(""), seed: int = typer.Option(0),
                 target: str = typer.Option("", help="Parameters to determine first, e.g. 'theta_6,wire_l0'."),
                 out: Optional[Path] = typer.Option(None, "--out", help="Write the proposed postures (CSV q1..qn)."),
                 as_json: bool = typer.Option(False, "--json")) -> None:
        """Which postures to measure next (same instrument as the first file) to determine the weakest parameters."""
        from spacearm.controller.calibration.composite import CompositeProblem
        from spacearm.controller.calibration.fit_checks import data_identifiability
        from spacearm.controller.calibration.pose_selection import next_postures, probe_block
        kin, em, blocks, cands, _ = _setup(data, model, sigma_pos, sigma_rot, plane, anchor, tool_point,
                                           register, frames, fix)
        rng = np.random.default_rng(seed)
        Qc = kin.random_configurations(candidates, rng, margin=0.05)
        # Candidates: what could be identified with rich data (the candidate postures), not only
        # what the data so far determine.
        wide = data_identifiability(CompositeProblem(em, [probe_block(blocks[0], Qc)], list(cands)), cands).kept
        targets = [t.strip() for t in target.split(",") if t.strip()]
        unknown = [t for t in targets if t not in wide]
        if unknown:
            raise BadInput(f"--target {', '.join(unknown)}: not identifiable with this instrument "
                           f"(identifiable: {', '.join(wide)})")
        nxt = next_postures(CompositeProblem(em, blocks, wide), blocks[0], Qc, count, targets or None)
        chosen = Qc[nxt.indices]
        if out is not None:
            np.savetxt(out, chosen, delimiter=",", header=",".join(f"q{i + 1}" for i in range(kin.nq)), comments="")
        if as_json:
            print(json.dumps({"postures": chosen.tolist(), "rank_before": nxt.rank_before, "rank_after": nxt.rank_after,
                              "std_before": nxt.std_before, "std_after": nxt.std_after}))
            return
        print(f"identifiable with rich data: {len(wide)} parameters; rank of the data so far {nxt.rank_before}, "
              f"with the {len(chosen)} proposed postures {nxt.rank_after}")
        print("most improved (predicted 1-sigma before -> after):")
        for n in nxt.most_improved(8):
            b, a = nxt.std_before[n], nxt.std_after[n]
            print(f"  {n:<12} {'unidentifiable' if not np.isfinite(b) else _fmt(n, b):>18} -> {_fmt(n, a)}")
        print("proposed postures (rad):")
        for q in chosen:
            print("  " + " ".join(f"{v:+.4f}" for v in q))


def _print_report(rep, opts) -> None:
    res = rep.result
    print(rep.identifiability.summary())
    weak = ", ".join(f"{n} {v:+.2f}" for n, v in rep.weakest.parameters.items())
    print(f"weakest direction (scaled singular value ratio {rep.weakest.sigma_ratio:.2e}): {weak}")
    print(f"\n{res.method}: {res.status} ({res.message}), {res.iterations} iterations, {rep.elapsed * 1e3:.1f} ms; "
          f"{rep.train_postures} training postures, residual {rep.noise_ratio:.2f}x the stated noise, "
          f"position RMS {rep.train_position_rms * 1e3:.4f} mm")
    scale = "scaled by the residual" if opts.noise == "residual" else "stated noise"
    print(f"estimates (+- 1 sigma, {scale}):")
    for name, value in res.estimate.items():
        print(f"  {name:<12} {_fmt(name, value):>18}  +- {_fmt(name, rep.std[name])}")
    if rep.regularised:
        unreg = "" if rep.held_unregularised is None else \
            f"; held-out RMS without it {rep.held_unregularised * 1e3:.4f} mm"
        print(f"regularised by default (weakly conditioned, singular value ratio {rep.weakest.sigma_ratio:.1e}): "
              f"prior 0.5 deg / 5 mm on the D-H terms{unreg}")
    if rep.selection is not None:
        print(rep.selection.summary())
    if rep.held_out:
        what = "validation postures (another session)" if rep.validation_file else "held-out postures"
        print(f"{what}: {len(rep.held_out)}, position error RMS {rep.held_rms('before') * 1e3:.4f} mm "
              f"(start values) -> {rep.held_rms('after') * 1e3:.4f} mm (fit)")
        n_out, rms_out = rep.held_rms_where(True)
        if n_out:
            n_in, rms_in = rep.held_rms_where(False)
            inside = f"{rms_in * 1e3:.4f} mm on the {n_in} inside" if n_in else "none inside"
            print(f"  extrapolation: {n_out} postures outside the training range of a joint, RMS {rms_out * 1e3:.4f} mm "
                  f"({inside})")
        for h in rep.worst_held_out(opts.worst):
            flag = f"  [outside the training range: {', '.join(h.outside)}]" if h.outside else ""
            print(f"  worst: {h.block} row {h.index}: {h.before * 1e3:.4f} -> {h.after * 1e3:.4f} mm{flag}")
        for h in (h for h in rep.held_out if h.outside and h.after > h.before):
            print(f"  extrapolated and worse: {h.block} row {h.index}: {h.before * 1e3:.4f} -> {h.after * 1e3:.4f} mm "
                  f"({', '.join(h.outside)})")
    print(rep.verdict.message())
