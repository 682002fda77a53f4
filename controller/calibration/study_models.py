"""Synthetic studies with a known truth, one per measurement model, and mis-modelled set-ups.

Each study draws a true arm (D-H errors of a few tenths of a millimetre / degree, plus errors of
the registration, tool and instrument parameters the model can see), measures it at random
postures with Gaussian noise, fits with `fit_blocks` and scores the fit on 200 independent
postures against the noise-free truth, in the measurement's position units (m):

  error  RMS over validation postures of |true reading - predicted reading| (position rows)
  floor  what the best unbiased estimator leaves on average: the Cramer-Rao covariance of the
         identifiable parameters on these postures, propagated to the validation readings,
         sqrt(mean_v trace(G_v C G_v^T)). error / floor ~ 1 means the fit used the data fully.

`mis_modelled_cases` builds set-ups whose assumed model is wrong (range data read as plane
distances, readings from two anchors read as one, a marker held 20 mm off, joint readings in
degrees, two joints swapped, poses in mm); the plausibility check must reject every one of them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spacearm.base.paths import CONFIGS
from spacearm.controller.calibration.composite import Block, CompositeProblem
from spacearm.controller.calibration.errormodel import ErrorModel
from spacearm.controller.calibration.measurement_models import (MeasurementModel, PlaneModel, PointModel,
                                                       PoseModel, RangeModel)
from spacearm.controller.calibration.trusted_fit import FitOptions, FitReport, fit_blocks
from spacearm.base.kinematics import load_model

Array = NDArray[np.float64]
ARMS = CONFIGS / "arm"
MODELS = ("pose", "point", "range", "plane")
NOISE = {"pose": [0.1e-3] * 3 + [np.radians(0.02)] * 3, "point": 0.1e-3, "range": 0.1e-3, "plane": 0.1e-3}


@dataclass
class Setup:
    em: ErrorModel
    model: MeasurementModel          # the instrument as assumed (nominal extras)
    true_model: MeasurementModel     # the instrument as it is
    sigma: object


def setup(kind: str, arm: str = "oru_testbed_6dof.toml") -> Setup:
    """Nominal arm and instrument for one measurement model (plane: the laser-ranger arm)."""
    if kind == "plane":
        em = ErrorModel.from_kinematics(load_model(ARMS / "space_robot_6dof_laser.toml"))
        return Setup(em, PlaneModel((0.0, 1.0, 4.6), -0.69), PlaneModel((0.0, 1.0, 4.605), -0.69), NOISE[kind])
    em = ErrorModel.from_kinematics(load_model(ARMS / arm))
    reach = em.kin.reach
    if kind == "pose":
        return Setup(em, PoseModel(), PoseModel(), NOISE[kind])
    if kind == "point":
        return Setup(em, PointModel((0.05, 0.0, 0.08)), PointModel((0.052, -0.0015, 0.081)), NOISE[kind])
    if kind == "range":
        a = (0.8 * reach, 0.3 * reach, 0.5 * reach)
        return Setup(em, RangeModel(a, 0.0, (0.0, 0.0, 0.05)),
                     RangeModel((a[0] + 0.004, a[1] - 0.003, a[2] + 0.005), 0.002, (0.001, -0.001, 0.052)),
                     NOISE[kind])
    raise ValueError(f"unknown measurement model {kind!r} ({', '.join(MODELS)})")


def true_parameters(st: Setup, rng: np.random.Generator) -> Array:
    """Nominal plus random D-H errors (0.1 deg, 0.5 mm) and, where the model sees them, frame errors."""
    em = st.em
    x = em.nominal.copy()
    for i, n in enumerate(em.names):
        kind = n.rsplit("_", 1)[0]
        if kind in ("theta", "alpha"):
            x[i] += rng.normal(0.0, np.radians(0.1))
        elif kind in ("a", "d"):
            x[i] += rng.normal(0.0, 0.5e-3)
        elif kind == "beta" and em.kin.beta_mask[int(n.rsplit("_", 1)[1]) - 1]:
            x[i] += rng.normal(0.0, np.radians(0.1))
    if isinstance(st.model, (PoseModel, PointModel)):
        for n in em.frame_names("world") + em.frame_names("tool"):
            x[em.index(n)] += rng.normal(0.0, 1e-3 if n[-1] in "xyz" and "_r" not in n else np.radians(0.1))
    return x


def valid_postures(st: Setup, x_true: Array, count: int, rng: np.random.Generator) -> Array:
    """Random postures within limits (plane: the beam hits the plane 0.1-3 m ahead, not grazing)."""
    kin = st.em.kin
    out: list[Array] = []
    while sum(len(o) for o in out) < count:
        Q = kin.random_configurations(4 * count, rng, margin=0.05)
        if isinstance(st.model, PlaneModel):
            T = st.em.poses(x_true, Q)
            n = np.asarray(st.model.normal)
            h = st.model.predict(T, st.model.extra_nominal)
            cos = np.abs(T[:, :3, 2] @ n) / np.linalg.norm(n)
            Q = Q[(h > 0.1) & (h < 3.0) & (cos > 0.3)]
        out.append(Q)
    return np.concatenate(out)[:count]


def readings(st: Setup, x_true: Array, Q: Array, rng: np.random.Generator | None) -> Array:
    """True instrument readings at Q, with noise when rng is given."""
    m = st.true_model
    T = st.em.poses(x_true, Q)
    clean = m.predict(T, m.extra_nominal)
    if rng is None:
        return clean
    sig = np.broadcast_to(np.asarray(st.sigma, float), (m.rows,))
    if isinstance(m, PoseModel):
        from spacearm.base.kinematics import rotvec_to_matrix
        out = clean.copy()
        out[:, :3, 3] += rng.normal(0.0, sig[:3], (len(Q), 3))
        for k in range(len(Q)):
            out[k, :3, :3] = rotvec_to_matrix(rng.normal(0.0, sig[3:], 3)) @ clean[k, :3, :3]
        return out
    return clean + rng.normal(0.0, sig[0], clean.shape)


@dataclass
class StudyRun:
    report: FitReport
    error: float          # m, RMS validation error against the truth
    floor: float          # m, Cramer-Rao expectation of the same


def run_once(st: Setup, m: int, seed: int, opts: FitOptions = FitOptions(holdout=0.0),
             n_valid: int = 200) -> StudyRun:
    rng = np.random.default_rng(seed)
    x_true = true_parameters(st, rng)
    Q = valid_postures(st, x_true, m, rng)
    Qv = valid_postures(st, x_true, n_valid, rng)
    block = Block(st.model, Q, readings(st, x_true, Q, rng), st.sigma)
    rep = fit_blocks(st.em, [block], opts)
    vb = Block(st.model, Qv, readings(st, x_true, Qv, None), st.sigma)
    vp = CompositeProblem(st.em, [vb], rep.result.free)
    err = vp.position_errors(rep.result.x)[0]
    error = float(np.sqrt(np.mean(np.sum(err ** 2, axis=1))))
    # Cramer-Rao: whitened training Jacobian at the truth-free estimate (linearisation point).
    tp = CompositeProblem(st.em, [block], rep.result.free)
    _, A = tp.residual_and_jacobian(rep.result.x)
    G = A[:, 0, tp.free_idx]
    C = np.linalg.pinv(G.T @ G, rcond=1e-12)
    rows = list(st.model.position_rows)
    _, Av = vp.block_residuals(rep.result.x)[0]
    Gv = Av[:, rows][:, :, vp.free_idx]                         # (Nv, r, L)
    floor = float(np.sqrt(np.mean(np.einsum("nrl,lk,nrk->n", Gv, C, Gv))))
    return StudyRun(rep, error, floor)


def study(kind: str, m: int, seeds: int = 6, seed0: int = 0, opts: FitOptions = FitOptions(holdout=0.0),
          arm: str = "oru_testbed_6dof.toml") -> tuple[float, list[StudyRun]]:
    """Pooled error / floor over `seeds` runs: sqrt(mean error^2) / sqrt(mean floor^2)."""
    st = setup(kind, arm)
    runs = [run_once(st, m, seed0 + k, opts) for k in range(seeds)]
    ratio = float(np.sqrt(np.mean([r.error ** 2 for r in runs]) / np.mean([r.floor ** 2 for r in runs])))
    return ratio, runs


# ------------------------------------------------------------------------------ mis-modelled
@dataclass
class MisModelled:
    name: str
    em: ErrorModel
    blocks: list[Block]
    fixed: tuple[str, ...] = ()      # parameters the set-up holds at their (wrong) values

    def candidates(self) -> list[str]:
        return [n for n in CompositeProblem(self.em, self.blocks, []).names if n not in self.fixed]


def mis_modelled_cases(seed: int = 0, m: int = 60) -> list[MisModelled]:
    """Set-ups whose assumed measurement model is wrong; each must be rejected."""
    rng = np.random.default_rng(seed)
    st = setup("range")
    x = true_parameters(st, rng)
    Q = valid_postures(st, x, m, rng)
    L = readings(st, x, Q, rng)
    # Half the readings taken from a second anchor 0.4 m away, all modelled as from the first.
    other = RangeModel(tuple(np.add(st.true_model.anchor, (0.0, 0.4, 0.0))), st.true_model.length_offset,
                       st.true_model.tool_point)
    L2 = L.copy()
    L2[::2] = other.predict(st.em.poses(x, Q[::2]), other.extra_nominal) + rng.normal(0.0, 1e-4, len(Q[::2]))
    cases = [MisModelled("range data read as laser distances to a plane", st.em,
                         [Block(PlaneModel((0.3, 0.1, 1.0), -1.0), Q, L, st.sigma)]),
             MisModelled("range data from two anchors read as one", st.em, [Block(st.model, Q, L2, st.sigma)])]
    stp = setup("point")
    x = true_parameters(stp, rng)
    Qp = valid_postures(stp, x, m, rng)
    P = readings(stp, x, Qp, rng)
    Qs = Qp.copy()
    Qs[:, [1, 2]] = Qs[:, [2, 1]]
    wrong_tip = PointModel((0.07, 0.0, 0.08))
    cases += [MisModelled("point data, marker held fixed 20 mm off", stp.em, [Block(wrong_tip, Qp, P, stp.sigma)],
                          ("marker_tx", "marker_ty", "marker_tz", "tool_x", "tool_y", "tool_z")),
              MisModelled("point data with joint angles in degrees", stp.em,
                          [Block(stp.model, np.degrees(Qp), P, stp.sigma)]),
              MisModelled("point data with joints 2 and 3 swapped", stp.em, [Block(stp.model, Qs, P, stp.sigma)])]
    sto = setup("pose")
    x = true_parameters(sto, rng)
    Qo = valid_postures(sto, x, m, rng)
    cases.append(MisModelled("pose data in millimetres", sto.em,
                             [Block(sto.model, Qo, _scale_poses(readings(sto, x, Qo, rng), 1e3), sto.sigma)]))
    return cases


def _scale_poses(T: Array, k: float) -> Array:
    out = T.copy()
    out[:, :3, 3] *= k
    return out
