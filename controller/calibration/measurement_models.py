"""Measurement models for calibration: what an instrument reads as a function of the arm's end pose.

Each model turns the end poses T (N, 4, 4) of an `ErrorModel` and their parameter Jacobian
(N, 6, P: base-frame twists at the end point, see errormodel.py) into predicted readings, a
residual r = measured - predicted and the Jacobians of the prediction with respect to the
arm parameters and to the model's own extra parameters (anchor, plane, tool point):

  PoseModel    6 rows  full pose (camera/PnP): (p_meas - p; log(R_meas R^T)), measurement frame
  CameraPoseModel  6 rows  the camera's pose from its own view of a target (board_T_cam), with the
                       camera's depth scale: a focal length off by a fraction s scales the target's
                       depth along the optical axis by 1 + s; extra: <prefix>_depth_scale
  BoardScaleModel  6 rows  the camera's pose from its view of a target whose pitch is off along
                       the target's x and y axes by fractions s_x, s_y (a printed board's scale per
                       print axis): the camera's position in the target frame scales by (1 + s) per
                       axis; extra: <prefix>_scale_x, <prefix>_scale_y
  PointModel   3 rows  a point on the tool, p + R t (motion-capture marker, laser-tracker SMR);
                       extra: tool point t = (<prefix>_tx, _ty, _tz) in the tool frame
  RangeModel   1 row   distance from a fixed anchor to a point on the tool plus a length offset,
                       |p + R t - a| + l0 (draw-wire, laser tracker in range mode);
                       extra: anchor a = (<prefix>_ax, _ay, _az), l0 = <prefix>_l0, tool point t
  PlaneModel   1 row   laser distance along tool +z to the plane n.p + f = 0 (laser-ranger paper
                       eq. 10); extra: (<prefix>_nx, _ny, _nz, _f) (scale gauge: one is fixed)

The measurement frame is the error model's world frame: its six small-motion parameters
(`base_*` or any world prefix) are the registration between the instrument and the arm base.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from spacearm.controller.calibration.residuals import rotvec_batch

Array = NDArray[np.float64]


def _tool_point(T: Array, Jt: Array, t: Array) -> tuple[Array, Array, Array]:
    """Point p + R t in the base frame (N, 3), its Jacobian wrt the arm (N, 3, P) and wrt t (N, 3, 3)."""
    Rt = np.einsum("nij,j->ni", T[:, :3, :3], t)
    p = T[:, :3, 3] + Rt
    # A rotation omega moves the offset R t by omega x (R t) = -(R t) x omega.
    dp = Jt[:, :3] - np.cross(Rt[:, :, None], Jt[:, 3:], axisa=1, axisb=1, axisc=1)
    return p, dp, T[:, :3, :3]


@dataclass(frozen=True)
class PoseModel:
    """Full 6-D pose of the tool frame in the measurement frame."""
    name: str = "pose"
    rows: int = 6
    extra_names: tuple[str, ...] = ()
    extra_nominal: Array = field(default_factory=lambda: np.zeros(0))
    position_rows: tuple[int, ...] = (0, 1, 2)

    def predict(self, T: Array, e: Array) -> Array:
        return T

    def residual(self, T: Array, Jt: Array, e: Array, measured: Array) -> tuple[Array, Array, Array]:
        r = np.empty((len(T), 6))
        r[:, :3] = measured[:, :3, 3] - T[:, :3, 3]
        r[:, 3:] = rotvec_batch(measured[:, :3, :3] @ np.swapaxes(T[:, :3, :3], 1, 2))
        return r, Jt, np.zeros((len(T), 6, 0))

    def as_rows(self, measured_or_predicted: Array) -> Array:
        """Position part of readings (N, 3): what validation errors are measured in."""
        return measured_or_predicted[:, :3, 3]


@dataclass(frozen=True)
class _CameraView:
    """A camera's pose in a target's frame from its own image of the target (board_T_cam), with
    `terms` of the camera or the target (zero when exact) as the model's extra parameters."""
    prefix: str = "camera"
    name: str = "pose"
    rows: int = 6
    position_rows: tuple[int, ...] = (0, 1, 2)
    terms: ClassVar[tuple[str, ...]] = ()

    @property
    def extra_names(self) -> tuple[str, ...]:
        return tuple(f"{self.prefix}_{t}" for t in self.terms)

    @property
    def extra_nominal(self) -> Array:
        return np.zeros(len(self.terms))

    def as_rows(self, measured_or_predicted: Array) -> Array:
        return measured_or_predicted[:, :3, 3]


@dataclass(frozen=True)
class CameraPoseModel(_CameraView):
    """The camera's pose in the target's frame from its own image of the target (PnP), whose
    distance along the optical axis is off by the fraction s of the focal length error.

    A focal length f(1 + s) in the intrinsics makes PnP place the target (1 + s) times as deep
    along the optical axis with the same lateral image position: in the target frame the camera
    sits at p - s (z . p) z, z the optical axis and z . p = -depth. A principal-point error is a
    tilt of the camera and already a tool-frame parameter; a wrong target size is a scale of every
    length, which the D-H and frame lengths carry; the depth scale is neither.
    """
    terms: ClassVar[tuple[str, ...]] = ("depth_scale",)

    def predict(self, T: Array, e: Array) -> Array:
        out = T.copy()
        z = T[:, :3, 2]
        out[:, :3, 3] = T[:, :3, 3] + e[0] * np.einsum("ni,ni->n", z, T[:, :3, 3])[:, None] * z
        return out

    def residual(self, T: Array, Jt: Array, e: Array, measured: Array) -> tuple[Array, Array, Array]:
        s = e[0]
        p, z = T[:, :3, 3], T[:, :3, 2]
        zp = np.einsum("ni,ni->n", z, p)
        r = PoseModel().residual(self.predict(T, e), Jt, e, measured)[0]   # the scale moves no rotation
        # d(zp z) = (z.dp + (w x z).p) z + zp (w x z), with (w x z).p = w.(z x p) and w x z = -[z]x w
        dp, w = Jt[:, :3], Jt[:, 3:]
        dzp = np.einsum("ni,nip->np", z, dp) + np.einsum("ni,nip->np", np.cross(z, p), w)
        wz = -np.cross(z[:, :, None], w, axisa=1, axisb=1, axisc=1)
        A = Jt.copy()
        A[:, :3] += s * (z[:, :, None] * dzp[:, None, :] + zp[:, None, None] * wz)
        A_e = np.zeros((len(T), 6, 1))
        A_e[:, :3, 0] = zp[:, None] * z
        return r, A, A_e


@dataclass(frozen=True)
class BoardScaleModel(_CameraView):
    """The camera's pose in the target's frame from its own image of a target whose pitch is off
    by fractions (s_x, s_y) along the target's own x and y axes: the pose estimate places the
    camera at (x (1 + s_x), y (1 + s_y), z) in the target frame. An equal scale of x, y and z is a
    scale of every length (the D-H and frame lengths carry it), so with the lengths free this term
    is the camera's lateral offsets against its height above the target; the rotation is untouched.
    """
    terms: ClassVar[tuple[str, ...]] = ("scale_x", "scale_y")

    def predict(self, T: Array, e: Array) -> Array:
        out = T.copy()
        out[:, :2, 3] = T[:, :2, 3] * (1.0 + e[:2])
        return out

    def residual(self, T: Array, Jt: Array, e: Array, measured: Array) -> tuple[Array, Array, Array]:
        r = PoseModel().residual(self.predict(T, e), Jt, e, measured)[0]
        A = Jt.copy()
        A[:, :2] *= (1.0 + e[:2])[None, :, None]
        A_e = np.zeros((len(T), 6, 2))
        A_e[:, 0, 0], A_e[:, 1, 1] = T[:, 0, 3], T[:, 1, 3]
        return r, A, A_e


@dataclass(frozen=True)
class PointModel:
    """A point fixed on the tool (marker, reflector), measured in 3-D."""
    tool_point: tuple[float, float, float] = (0.0, 0.0, 0.0)
    prefix: str = "marker"
    name: str = "point"
    rows: int = 3
    position_rows: tuple[int, ...] = (0, 1, 2)

    @property
    def extra_names(self) -> tuple[str, ...]:
        return tuple(f"{self.prefix}_{k}" for k in ("tx", "ty", "tz"))

    @property
    def extra_nominal(self) -> Array:
        return np.array(self.tool_point, float)

    def predict(self, T: Array, e: Array) -> Array:
        return T[:, :3, 3] + np.einsum("nij,j->ni", T[:, :3, :3], e)

    def residual(self, T: Array, Jt: Array, e: Array, measured: Array) -> tuple[Array, Array, Array]:
        p, dp, dt = _tool_point(T, Jt, e)
        return measured - p, dp, dt

    def as_rows(self, values: Array) -> Array:
        return values


@dataclass(frozen=True)
class RangeModel:
    """Distance from a fixed anchor to a point on the tool, plus a constant length offset."""
    anchor: tuple[float, float, float]
    length_offset: float = 0.0
    tool_point: tuple[float, float, float] = (0.0, 0.0, 0.0)
    prefix: str = "wire"
    name: str = "range"
    rows: int = 1
    position_rows: tuple[int, ...] = (0,)

    @property
    def extra_names(self) -> tuple[str, ...]:
        return tuple(f"{self.prefix}_{k}" for k in ("ax", "ay", "az", "l0", "tx", "ty", "tz"))

    @property
    def extra_nominal(self) -> Array:
        return np.array([*self.anchor, self.length_offset, *self.tool_point], float)

    def predict(self, T: Array, e: Array) -> Array:
        p = T[:, :3, 3] + np.einsum("nij,j->ni", T[:, :3, :3], e[4:7])
        return np.linalg.norm(p - e[:3], axis=1) + e[3]

    def residual(self, T: Array, Jt: Array, e: Array, measured: Array) -> tuple[Array, Array, Array]:
        p, dp, dt = _tool_point(T, Jt, e[4:7])
        v = p - e[:3]
        dist = np.linalg.norm(v, axis=1)
        u = v / np.maximum(dist, 1e-12)[:, None]
        r = (np.reshape(measured, -1) - dist - e[3])[:, None]
        A_arm = np.einsum("ni,nip->np", u, dp)[:, None, :]
        A_e = np.empty((len(T), 1, 7))
        A_e[:, 0, :3] = -u
        A_e[:, 0, 3] = 1.0
        A_e[:, 0, 4:] = np.einsum("ni,nij->nj", u, dt)
        return r, A_arm, A_e

    def as_rows(self, values: Array) -> Array:
        return np.reshape(values, (-1, 1))


@dataclass(frozen=True)
class PlaneModel:
    """Laser ranger on the tool: distance along tool +z from the tool origin to a plane."""
    normal: tuple[float, float, float]
    offset: float
    prefix: str = "plane"
    name: str = "plane"
    rows: int = 1
    position_rows: tuple[int, ...] = (0,)

    @property
    def extra_names(self) -> tuple[str, ...]:
        return tuple(f"{self.prefix}_{k}" for k in ("nx", "ny", "nz", "f"))

    @property
    def extra_nominal(self) -> Array:
        return np.array([*self.normal, self.offset], float)

    def gauge(self) -> str:
        """The coefficient held fixed for scale: the largest normal component."""
        return self.extra_names[int(np.argmax(np.abs(self.normal)))]

    def predict(self, T: Array, e: Array) -> Array:
        return -(T[:, :3, 3] @ e[:3] + e[3]) / (T[:, :3, 2] @ e[:3])

    def residual(self, T: Array, Jt: Array, e: Array, measured: Array) -> tuple[Array, Array, Array]:
        n, f = e[:3], e[3]
        ps, bl = T[:, :3, 3], T[:, :3, 2]
        nb = bl @ n
        h = -(ps @ n + f) / nb
        r = (np.reshape(measured, -1) - h)[:, None]
        # d bl = omega x bl; dh = -n.(dps + h dbl) / (n.bl)  (same as residuals.Problem)
        dbl = np.cross(np.swapaxes(Jt[:, 3:], 1, 2), bl[:, None, :])
        dps = np.swapaxes(Jt[:, :3], 1, 2)
        A_arm = (-((dps + h[:, None, None] * dbl) @ n) / nb[:, None])[:, None, :]
        A_e = np.empty((len(T), 1, 4))
        A_e[:, 0, :3] = -(ps + h[:, None] * bl) / nb[:, None]
        A_e[:, 0, 3] = -1.0 / nb
        return r, A_arm, A_e

    def as_rows(self, values: Array) -> Array:
        return np.reshape(values, (-1, 1))


MeasurementModel = PoseModel | CameraPoseModel | BoardScaleModel | PointModel | RangeModel | PlaneModel
