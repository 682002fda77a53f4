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
from spacearm.controller.calibration.errormodel import ErrorModel
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


def _kabsch(P: Array, Q: Array) -> Array:
    """Rigid transform T with Q ~= T P (rows are points)."""
    cp, cq = P.mean(0), Q.mean(0)
    U, _, Vt = np.linalg.svd((P - cp).T @ (Q - cq))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = cq - R @ cp
    return T


def initial_registration(em: ErrorModel, blocks: list[Block]) -> Array:
    """Measurement frame <- arm base from the point and pose data at the nominal model (Kabsch),
    so that a motion-capture or tracker frame need not be registered by hand."""
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
    return _kabsch(np.concatenate(P), np.concatenate(M))
