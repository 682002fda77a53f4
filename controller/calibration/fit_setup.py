"""From measurement files and instrument settings to the blocks of a composite fit.

One file per instrument (datafile.py infers pose / position / range / plane from its columns).
Settings that the files cannot carry (plane equation, anchor, tool point, noise) come from the
command line; anything that does not fit raises `SetupError` with one line saying why.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from spacearm.controller.calibration.composite import Block
from spacearm.controller.calibration.datafile import DataFileError, read_measurements
from spacearm.controller.calibration.errormodel import ErrorModel, prismatic_joints
from spacearm.controller.calibration.instrument_start import kabsch, register_points
from spacearm.controller.calibration.measurement_models import PlaneModel, PointModel, PoseModel, RangeModel
from spacearm.base.kinematics import KinematicModel

Array = NDArray[np.float64]


class SetupError(ValueError):
    """The files or settings cannot describe a calibration problem (message says why)."""


@dataclass(frozen=True)
class Instruments:
    sigma_pos: float = 0.3e-3                       # m, position / distance noise (1 sigma)
    sigma_rot: float = np.radians(0.5)              # rad, orientation noise of pose data
    plane: tuple[float, ...] | None = None          # nx, ny, nz, f
    anchor: tuple[float, ...] | None = None         # ax, ay, az[, l0]
    tool_point: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        for what, value in (("--sigma-pos", self.sigma_pos), ("--sigma-rot", self.sigma_rot)):
            if not (np.isfinite(value) and value > 0):
                raise SetupError(f"{what} must be a positive noise level (1 sigma, SI), got {value!r}")


def parse_vector(text: str, sizes: tuple[int, ...], what: str) -> tuple[float, ...] | None:
    """'1,2,3' -> (1.0, 2.0, 3.0); empty -> None; wrong count or not numbers -> SetupError."""
    if not text:
        return None
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise SetupError(f"{what}: {text!r} is not a comma-separated list of numbers") from None
    if len(vals) not in sizes or not all(np.isfinite(vals)):
        raise SetupError(f"{what} needs {' or '.join(map(str, sizes))} finite numbers, got {text!r}")
    return vals


def load_blocks(files: list[Path], kin: KinematicModel, inst: Instruments) -> list[Block]:
    """One block per file, measurement model from the file's kind and the instrument settings."""
    blocks = []
    for k, path in enumerate(files):
        try:
            mf = read_measurements(path, kin.nq)
        except DataFileError as exc:
            raise SetupError(str(exc)) from None
        if not np.all(np.isfinite(mf.Q)) or not np.all(np.isfinite(mf.measured)):
            raise SetupError(f"{path}: non-finite values (nan/inf) in the data")
        if len(mf.Q) < 2:
            raise SetupError(f"{path}: need at least two postures")
        check_units(path, kin, mf.kind, mf.Q, mf.measured)
        suffix = "" if k == 0 else str(k + 1)
        if mf.kind == "pose":
            model, sigma = PoseModel(), [inst.sigma_pos] * 3 + [inst.sigma_rot] * 3
        elif mf.kind == "position":
            model, sigma = PointModel(inst.tool_point, prefix="marker" + suffix), inst.sigma_pos
        elif mf.kind == "range":
            if inst.anchor is None:
                raise SetupError(f"{path}: range data need --anchor 'ax,ay,az[,l0]' (approximate anchor, m)")
            l0 = inst.anchor[3] if len(inst.anchor) == 4 else 0.0
            model = RangeModel(tuple(inst.anchor[:3]), l0, inst.tool_point, prefix="wire" + suffix)
            sigma = inst.sigma_pos
        else:
            if inst.plane is None:
                raise SetupError(f"{path}: distance data need --plane 'nx,ny,nz,f'")
            model, sigma = PlaneModel(tuple(inst.plane[:3]), inst.plane[3], prefix="plane" + suffix), inst.sigma_pos
        blocks.append(Block(model, mf.Q, mf.measured, sigma, label=Path(path).name))
    return blocks


LIMIT_SLACK = 0.05        # rad (m for a prismatic joint) beyond the arm file's limits still accepted
SCALE_SLACK = 10.0        # readings may spread over this many arm reaches before they are not metres


def check_units(path: Path, kin: KinematicModel, kind: str, Q: Array, measured: Array) -> None:
    """One line naming the likely unit when joints leave the arm's limits (degrees? mm?) or the
    readings spread far beyond the arm's reach (mm?)."""
    lo, hi = np.asarray(kin.q_min, float) - LIMIT_SLACK, np.asarray(kin.q_max, float) + LIMIT_SLACK
    prismatic = prismatic_joints(kin)
    bad = np.flatnonzero(np.any((Q < lo) | (Q > hi), axis=0))
    if bad.size:
        j = int(bad[0])
        worst = float(Q[np.argmax(np.abs(Q[:, j])), j])
        scale, unit, want = (1e-3, "mm", "m") if prismatic[j] else (np.pi / 180.0, "degrees", "rad")
        fits = np.all((Q[:, bad] * scale >= lo[bad]) & (Q[:, bad] * scale <= hi[bad]))
        hint = f": the values look like {unit} ({want} expected)" if fits else ""
        raise SetupError(f"{path}: joint q{j + 1} = {worst:.6g} is outside the arm's limits "
                         f"[{kin.q_min[j]:.4g}, {kin.q_max[j]:.4g}] {want}{hint}")
    reach = float(kin.reach)
    if kind == "range":
        size, what = float(np.median(np.abs(measured))), "median range"
    elif kind in ("position", "pose"):
        pts = measured if kind == "position" else measured[:, :3, 3]
        size, what = float(np.max(np.linalg.norm(pts - pts.mean(axis=0), axis=1))), "spread of the points"
    else:
        return
    if size > SCALE_SLACK * reach:
        hint = ": the values look like mm (m expected)" if size * 1e-3 <= SCALE_SLACK * reach else ""
        raise SetupError(f"{path}: {what} {size:.6g} is more than {SCALE_SLACK:g}x the arm's reach "
                         f"({reach:.3g} m){hint}")


def initial_registration(em: ErrorModel, blocks: list[Block]) -> Array:
    """Measurement frame <- arm base from the point and pose data at the nominal model (Kabsch),
    so that a motion-capture or tracker frame need not be registered by hand. With one marker's
    data, the marker's point on the tool is estimated with it, so neither depends on --tool-point."""
    points = [b for b in blocks if isinstance(b.model, PointModel)]
    if points and len(points) == len(blocks) and len({id(b.model) for b in points}) == 1 \
            and sum(len(b.Q) for b in points) >= 3:
        T = np.concatenate([em.poses(em.nominal, b.Q) for b in points])
        M = np.concatenate([b.measured for b in points])
        W, _ = register_points(T[:, :3, 3], T[:, :3, :3], M, np.asarray(points[0].model.tool_point, float))
        return W
    P, M = [], []
    for b in blocks:
        T = em.poses(em.nominal, b.Q)
        if isinstance(b.model, PoseModel):
            P.append(T[:, :3, 3])
            M.append(b.measured[:, :3, 3])
        elif isinstance(b.model, PointModel):
            P.append(b.model.predict(T, b.model.extra_nominal))
            M.append(b.measured)
    if not P or sum(len(p) for p in P) < 3:
        raise SetupError("registration needs point or pose data (at least 3 postures)")
    return kabsch(np.concatenate(P), np.concatenate(M))
