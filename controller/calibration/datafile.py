"""CSV measurement files for `spacearm calibrate fit`.

One row per posture: joint angles q1..qn (rad), then one of
  pose      T_00..T_23 (top 3 rows of the measured 4x4 pose, metres)
  position  x, y, z (metres)
  plane     h (laser distance, metres)
  range     range (distance from an anchor to a point on the tool, metres: draw-wire, tracker)
The kind is inferred from the columns present.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


class DataFileError(ValueError):
    """The file is not a usable calibration data file (message says why)."""


@dataclass
class MeasurementFile:
    kind: str
    Q: Array
    measured: Array


def read_measurements(path: Path, n_joints: int) -> MeasurementFile:
    path = Path(path)
    try:
        with path.open(newline="") as fh:
            rows = list(csv.DictReader(fh))
    except OSError as exc:
        raise DataFileError(f"cannot read {path}: {exc.strerror}") from None
    if not rows:
        raise DataFileError(f"{path}: no data rows")
    cols = set(rows[0])
    qcols = [f"q{i + 1}" for i in range(n_joints)]
    if not set(qcols) <= cols:
        raise DataFileError(f"{path}: needs columns {', '.join(qcols)}")
    pose_cols = [f"T_{i}{j}" for i in range(3) for j in range(4)]
    try:
        Q = np.array([[float(r[c]) for c in qcols] for r in rows])
        if set(pose_cols) <= cols:
            M = np.zeros((len(rows), 4, 4))
            M[:, 3, 3] = 1.0
            M[:, :3, :] = np.array([[float(r[c]) for c in pose_cols] for r in rows]).reshape(-1, 3, 4)
            return MeasurementFile("pose", Q, M)
        if {"x", "y", "z"} <= cols:
            return MeasurementFile("position", Q, np.array([[float(r[c]) for c in "xyz"] for r in rows]))
        if "h" in cols:
            return MeasurementFile("plane", Q, np.array([float(r["h"]) for r in rows]))
        if "range" in cols:
            return MeasurementFile("range", Q, np.array([float(r["range"]) for r in rows]))
    except (TypeError, ValueError) as exc:
        raise DataFileError(f"{path}: bad number ({exc})") from None
    raise DataFileError(f"{path}: needs pose columns T_00..T_23, or x,y,z, or h, or range")


def write_measurements(path: Path, Q: Array, kind: str, measured: Array) -> None:
    path = Path(path)
    n = Q.shape[1]
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        if kind == "pose":
            extra = [f"T_{i}{j}" for i in range(3) for j in range(4)]
            vals = measured[:, :3, :].reshape(len(Q), 12)
        elif kind == "position":
            extra, vals = ["x", "y", "z"], measured
        else:
            extra, vals = ["h" if kind == "plane" else "range"], measured.reshape(-1, 1)
        w.writerow([f"q{i + 1}" for i in range(n)] + extra)
        for q, v in zip(Q, vals):
            w.writerow([repr(float(x)) for x in q] + [repr(float(x)) for x in v])
