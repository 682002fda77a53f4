"""Synthetic set-ups shaped like real ones, with a known truth: the draw-wire case and random set-ups.

Real calibration data are not spread uniformly over the joint space: postures come from a
recorded motion (joints move together, some barely at all), instruments sit where they fit, and
their placement is known only roughly. These cases reproduce that so the fit is tested the way
users run it:

  draw_wire_case   a 6-DOF arm (the ORU test bed), ~1000 postures along a smooth recorded motion,
                   wrist joint 4 spanning ~10 deg, the anchor ~0.5 m from the base, wire
                   0.5-1.2 m, 0.5 mm sensor noise, the anchor start 0.15 m off per axis; a
                   validation set from another "day" (another motion) scored against the
                   truth-parameter floor (the same readings predicted by the true geometry).
  random_setup     one of range, point, plane or pose data on an arm of 6-8 joints (prismatic
                   included), random or recorded postures, random noise and start errors.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from spacearm.base.kinematics import KinematicModel, load_model
from spacearm.base.paths import CONFIGS
from spacearm.controller.calibration.composite import Block, CompositeProblem
from spacearm.controller.calibration.errormodel import ErrorModel, prismatic_joints
from spacearm.controller.calibration.measurement_models import (MeasurementModel, PlaneModel, PointModel,
                                                                PoseModel, RangeModel)

Array = NDArray[np.float64]
ARMS = ("oru_testbed_6dof.toml", "ur10.toml", "space_robot_6dof_laser.toml", "panda.toml", "ssrms_7dof.toml",
        "oru_testbed_on_rail.toml", "tiago")
KINDS = ("range", "point", "plane", "pose")


@dataclass
class Case:
    em: ErrorModel
    blocks: list[Block]              # training readings, instrument at its approximate start
    validation: list[Block]          # readings of another motion, same instrument
    truth: Array                     # true arm parameters
    true_model: MeasurementModel     # the instrument as it is
    frames: bool = False             # the registration/tool frames are candidates too

    def candidates(self) -> list[str]:
        names = CompositeProblem(self.em, self.blocks, []).names
        frame = set(self.em.frame_names("world") + self.em.frame_names("tool"))
        return [n for n in names if self.frames or n not in frame]

    def truth_floor(self) -> float:
        """RMS over the validation postures of the position error the true geometry leaves (m):
        the noise of the validation readings, what no fit can beat."""
        blocks = [Block(self.true_model, b.Q, b.measured, b.sigma, label=b.label) for b in self.validation]
        pr = CompositeProblem(self.em, blocks, [])
        err = pr.position_errors(np.concatenate([self.truth, self.true_model.extra_nominal]))
        return float(np.sqrt(np.mean(np.concatenate([np.sum(e ** 2, axis=1) for e in err]))))


@lru_cache(maxsize=None)
def arm(name: str) -> KinematicModel:
    """An arm file from configs/arm, or 'tiago': the TIAGo arm with its prismatic torso from its URDF."""
    if name == "tiago":
        from spacearm.base.kinematics.arm_import import import_arm
        _, cfg = import_arm(CONFIGS / "urdf" / "tiago" / "tiago_no_hand.urdf", "base_link", "arm_tool_link")
        return KinematicModel.from_config(cfg)
    return load_model(CONFIGS / "arm" / name)


def recorded_postures(kin: KinematicModel, count: int, rng: np.random.Generator,
                      narrow: dict[int, float] | None = None) -> Array:
    """Postures along a smooth recorded motion: every joint one slow sine (0.2-0.8 rad, or up to a
    third of a short joint's range) about a random centre, clipped to its limits; joints in
    `narrow` (index -> half span, rad) barely move."""
    t = np.linspace(0.0, 1.0, count)[:, None]
    lo, hi = np.asarray(kin.q_min, float), np.asarray(kin.q_max, float)
    centre = lo + (hi - lo) * rng.uniform(0.2, 0.8, kin.nq)
    amp = np.minimum(rng.uniform(0.2, 0.8, kin.nq), (hi - lo) / 3.0)
    for j, half in (narrow or {}).items():
        amp[j] = half
    freq = rng.uniform(2.0, 15.0, kin.nq) * 2.0 * np.pi
    phase = rng.uniform(0.0, 2.0 * np.pi, kin.nq)
    return np.clip(centre + amp * np.sin(freq * t + phase), lo, hi)


def perturbed_arm(em: ErrorModel, rng: np.random.Generator, angle: float = np.radians(0.1),
                  length: float = 0.5e-3) -> Array:
    """Nominal D-H plus Gaussian errors (beta only where the arm models it)."""
    x = em.nominal.copy()
    for i, n in enumerate(em.names):
        kind, _, j = n.rpartition("_")
        if kind in ("theta", "alpha") or (kind == "beta" and em.kin.beta_mask[int(j) - 1]):
            x[i] += rng.normal(0.0, angle)
        elif kind in ("a", "d"):
            x[i] += rng.normal(0.0, length)
    return x


def _wire_postures(em: ErrorModel, x: Array, model: RangeModel, count: int, rng: np.random.Generator,
                   narrow: dict[int, float]) -> Array:
    """Recorded-motion postures whose wire length stays within 0.5-1.2 m."""
    out: list[Array] = []
    while sum(len(o) for o in out) < count:
        Q = recorded_postures(em.kin, 8 * count, rng, narrow)
        L = model.predict(em.poses(x, Q), model.extra_nominal) - model.length_offset
        out.append(Q[(L > 0.5) & (L < 1.2)])
    return np.concatenate(out)[:count]


def draw_wire_case(seed: int, count: int = 1000, noise: float = 0.5e-3, start_error: float = 0.15) -> Case:
    """The draw-wire set-up of a 6-DOF industrial arm (module docstring)."""
    rng = np.random.default_rng(seed)
    em = ErrorModel.from_kinematics(arm("oru_testbed_6dof.toml"))
    x = perturbed_arm(em, rng)
    d = rng.normal(size=3)
    anchor = rng.uniform(0.4, 0.6) * d / np.linalg.norm(d)
    point = rng.normal(0.0, 0.03, 3)
    true = RangeModel(tuple(anchor), float(rng.uniform(-0.03, 0.03)), tuple(point))
    narrow = {3: np.radians(5.0)}
    start = RangeModel(tuple(anchor + rng.choice([-1.0, 1.0], 3) * start_error), 0.0, (0.0, 0.0, 0.0))

    # One recorded motion; a third of its postures, drawn at random, are the validation session
    # (the same motion measured again on another day).
    Q = _wire_postures(em, x, true, count + count // 2, rng, narrow)
    L = true.predict(em.poses(x, Q), true.extra_nominal) + rng.normal(0.0, noise, len(Q))
    order = rng.permutation(len(Q))
    train, valid = np.sort(order[:count]), np.sort(order[count:])
    return Case(em, [Block(start, Q[train], L[train], noise, label="wire")],
                [Block(start, Q[valid], L[valid], noise, label="wire-validation")], x, true)


def random_setup(seed: int, max_postures: int = 120) -> Case:
    """One random realistic set-up (module docstring); several arms, four instruments."""
    rng = np.random.default_rng(seed)
    kin = arm(ARMS[rng.integers(len(ARMS))])
    kind = KINDS[rng.integers(len(KINDS))]
    if kind == "plane":      # the laser ranger looks along the tool z: only its arm has the geometry
        kin = arm("space_robot_6dof_laser.toml")
    em = ErrorModel.from_kinematics(kin)
    x = perturbed_arm(em, rng, np.radians(rng.uniform(0.02, 0.3)), rng.uniform(0.1e-3, 2e-3))
    reach = kin.reach
    noise = float(rng.uniform(0.05e-3, 1e-3))
    off = rng.uniform(0.0, 0.05)
    if kind == "range":
        d = rng.normal(size=3)
        anchor = rng.uniform(0.3, 1.0) * reach * d / np.linalg.norm(d)
        true: MeasurementModel = RangeModel(tuple(anchor), float(rng.uniform(-0.05, 0.05)),
                                            tuple(rng.normal(0.0, 0.03, 3)))
        start: MeasurementModel = RangeModel(tuple(anchor + rng.normal(0.0, off, 3)), 0.0, (0.0, 0.0, 0.0))
        sigma: object = noise
    elif kind == "point":
        tp = rng.normal(0.0, 0.05, 3)
        true, start, sigma = PointModel(tuple(tp)), PointModel(tuple(tp + rng.normal(0.0, 0.01, 3))), noise
    elif kind == "plane":
        true, start, sigma = PlaneModel((0.0, 1.0, 4.605), -0.69), PlaneModel((0.0, 1.0, 4.6), -0.69), noise
    else:
        true, start, sigma = PoseModel(), PoseModel(), [noise] * 3 + [noise / 0.3] * 3
    frames = kind in ("point", "pose") and rng.uniform() < 0.5
    n = int(rng.integers(40, max_postures))
    recorded = rng.uniform() < 0.5

    def postures(count: int) -> Array:
        out: list[Array] = []
        while sum(len(o) for o in out) < count:
            if recorded:
                narrow = {int(rng.integers(kin.nq)): np.radians(rng.uniform(2.0, 10.0))}
                Q = recorded_postures(kin, 4 * count, rng, narrow)
            else:
                Q = kin.random_configurations(4 * count, rng, margin=0.05)
            if isinstance(true, PlaneModel):
                T = em.poses(x, Q)
                h = true.predict(T, true.extra_nominal)
                cos = np.abs(T[:, :3, 2] @ np.asarray(true.normal)) / np.linalg.norm(true.normal)
                Q = Q[(h > 0.1) & (h < 3.0) & (cos > 0.3)]
            out.append(Q)
        return np.concatenate(out)[:count]

    Q_all = postures(n + 60)
    order = rng.permutation(len(Q_all))

    def block(rows: Array, label: str) -> Block:
        Q = Q_all[np.sort(rows)]
        clean = true.predict(em.poses(x, Q), true.extra_nominal)
        if isinstance(true, PoseModel):
            from spacearm.base.kinematics import rotvec_to_matrix
            meas = clean.copy()
            meas[:, :3, 3] += rng.normal(0.0, noise, (len(Q), 3))
            for k in range(len(Q)):
                meas[k, :3, :3] = rotvec_to_matrix(rng.normal(0.0, noise / 0.3, 3)) @ clean[k, :3, :3]
        else:
            meas = clean + rng.normal(0.0, noise, np.shape(clean))
        return Block(start, Q, meas, sigma, label=label)
    # The validation session: postures of the same motion (or distribution) not used to fit.
    return Case(em, [block(order[:n], kind)], [block(order[n:], kind + "-validation")], x, true, frames)


def has_prismatic(case: Case) -> bool:
    return bool(prismatic_joints(case.em.kin).any())
