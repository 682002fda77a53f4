"""The impedance control loop of Figure 16 as a daemon Mode (one contact subtask).

Each cycle: gravity-compensate the measured wrench (eq. 14), express it in the task frame
about the compliance centre, run the per-axis admittance on the impedance axes (eq. 15/20),
advance the insertion axis (task z) by dstep in position mode until the force opposing the
motion exceeds F_tz (or a distance is covered), form X_d from the start pose X0 and the
regulated pose dX (eq. 21) and map it to joint targets by two damped least-squares steps
from the last command. Sign convention: the sensor reports the wrench ON the end effector,
so X_d = X0 + dX moves the tool the way the contact pushes it (the paper's X0 - dX with the
opposite sensor sign). The first `tare_cycles` cycles hold still and average the
gravity-compensated reading as the sensor bias (a software tare, out of contact).

`rate` (0..1, set by whoever pauses the task) scales the task's own progress: the insertion
step, the timer of a timed task and the stop counters. The admittance runs on at full rate, so
a paused contact keeps regulating its force (it holds the reference, not a rigid position) and
resumes with the same admittance state: no jump in force or in the commanded motion.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from spacearm.controller.modes import ModeBase
from spacearm.controller.cycle import Finding, FindingCode, Measurement
from spacearm.controller.impedance.admittance import Admittance
from spacearm.controller.impedance.config import ImpedanceParams
from spacearm.controller.impedance.gravity import GravityModel
from spacearm.base.kinematics.forward import fk
from spacearm.base.kinematics.jacobian import fk_jacobian
from spacearm.base.kinematics.model import KinematicData, KinematicModel
from spacearm.base.kinematics.pose_error import twist_error
from spacearm.base.spatial import cross3, rotvec_to_matrix
from spacearm.controller.planning.joint_move import JointSetpoint

AXIS_MODES = ("impedance", "hold", "step")
IK_DAMPING = 1.0e-3
SLIDE_SPEED = 1.0e-3     # m/s: slower lateral admittance motion than this counts as not sliding


@dataclass(frozen=True)
class ContactTask:
    name: str
    task_rotation: np.ndarray                   # base_R_task; z: insertion axis, out of the slot
    axes: tuple[str, ...]                       # per task axis: impedance | hold | step (z only)
    gravity: GravityModel
    sensor_offset: float                        # m: sensor origin behind the tool point, tool axis
    step: float = 0.0                           # m per cycle along task z (negative: into the slot)
    stop: str = "force"                         # force | distance | time
    travel: float = 0.05                        # m: distance to cover, or most to go looking for contact
    duration: float = 0.0                       # s, for stop = "time"
    compliance_center: np.ndarray = field(default_factory=lambda: np.zeros(3))   # m, tool frame
    stiffness: tuple[float, ...] | None = None  # overrides of the configured K_d / B_d
    damping: tuple[float, ...] | None = None
    settle_cycles: int = 10
    tare_cycles: int = 10
    bias: np.ndarray | None = None              # sensor bias from an earlier tare (tare_cycles = 0)
    seat_travel: float | None = None            # m the step axis must cover to be seated
    seat_tolerance: float = 0.005               # m

    def __post_init__(self) -> None:
        if len(self.axes) != 6 or any(a not in AXIS_MODES for a in self.axes):
            raise ValueError(f"axes must be 6 of {AXIS_MODES}, got {self.axes}")
        if any(a == "step" for i, a in enumerate(self.axes) if i != 2):
            raise ValueError("only task z (the insertion axis) can be a step axis")
        if self.stop not in ("force", "distance", "time"):
            raise ValueError(f"stop must be force, distance or time, got {self.stop!r}")


@dataclass
class ContactPeaks:
    force: float = 0.0           # N, |F| of the compensated contact force
    lateral_force: float = 0.0   # N, |(Fx, Fy)| in the task frame
    torque: float = 0.0          # N m, |T| about the compliance centre
    insert_force: float = 0.0    # N, force opposing the step axis


class ImpedanceMode(ModeBase):
    def __init__(self, model: KinematicModel, params: ImpedanceParams, task: ContactTask,
                 q_start: np.ndarray, description: str = ""):
        self.name = task.name
        self.description = description or task.name
        self.model = model
        self.params = params
        self.task = task
        self.data = KinematicData(model)
        self.q_cmd = np.asarray(q_start, float).copy()
        self.X0 = fk(model, self.data, self.q_cmd).copy()
        k = np.asarray(task.stiffness if task.stiffness is not None else params.stiffness, float)
        b = np.asarray(task.damping if task.damping is not None else params.damping, float)
        self.admittance = Admittance(k, b, params.period)
        self.impedance_axes = np.array([a == "impedance" for a in task.axes])
        self.bias = np.zeros(6) if task.bias is None else np.asarray(task.bias, float).copy()
        self._tare_sum = np.zeros(6)
        self._tare_count = 0
        self.travelled = 0.0
        self.stopped = False
        self.elapsed = 0.0
        self.settled = 0
        self.above = 0
        self._lateral_history: deque = deque(maxlen=task.settle_cycles + 1)
        self.last_wrench = np.zeros(6)       # task frame, compensated
        self.last_dx = np.zeros(6)
        self.peaks = ContactPeaks()
        self._failure: Finding | None = None
        self.rate = 1.0                      # of the task's progress (pause/resume ramps); 0: held

    # ---- Mode (update() in ModeBase) -----------------------------------------------------------------
    def _next_setpoint(self, t: float, m: Measurement) -> JointSetpoint:
        zeros = np.zeros_like(self.q_cmd)
        if self._failure is not None:
            return JointSetpoint(self.q_cmd.copy(), zeros, zeros)
        T = fk(self.model, self.data, m.q)
        R = T[:3, :3]
        compensated = self.task.gravity.compensate(m.wrench, R)
        if self._tare_count < self.task.tare_cycles:
            self._tare_sum += compensated
            self._tare_count += 1
            if self._tare_count == self.task.tare_cycles:
                self.bias = self._tare_sum / self._tare_count
            return JointSetpoint(self.q_cmd.copy(), zeros, zeros)
        w = self._task_wrench(T, compensated - self.bias)
        self.last_wrench = w
        if self._over_limit(w):
            return JointSetpoint(self.q_cmd.copy(), zeros, zeros)
        dx = np.zeros(6)
        adm = self.admittance.update(w - self.params.vector("desired_wrench"))
        dx[self.impedance_axes] = adm[self.impedance_axes]
        if self.rate > 0.0:
            self._advance(w)
        if self.task.axes[2] == "step":
            dx[2] = np.sign(self.task.step) * self.travelled
        self.last_dx = dx
        q_new = self._inverse(self._pose(dx))
        dq = (q_new - self.q_cmd) / self.params.period
        self.q_cmd = q_new
        return JointSetpoint(q_new.copy(), dq, zeros)

    def _finished(self, t: float) -> bool:
        settle = 0 if self.task.stop == "force" else self.task.settle_cycles
        return self.stopped and self.settled >= settle and self._failure is None

    def _progress(self, t: float) -> float:
        if self.task.stop == "time":
            return min(1.0, self.elapsed / self.task.duration) if self.task.duration > 0 else 1.0
        if self.stopped:
            return 1.0
        return min(0.99, self.travelled / self.task.travel) if self.task.travel > 0 else 0.0

    # ---- the loop's parts --------------------------------------------------------------
    def _task_wrench(self, T: np.ndarray, w_sensor: np.ndarray) -> np.ndarray:
        """Sensor-frame wrench -> task frame, torque about the compliance centre."""
        R, p = T[:3, :3], T[:3, 3]
        sensor_origin = p - self.task.sensor_offset * R[:, 2]
        centre = p + R @ self.task.compliance_center
        f = R @ w_sensor[:3]
        tau = R @ w_sensor[3:] + np.array(cross3((sensor_origin - centre).tolist(), f.tolist()))
        Rt = self.task.task_rotation
        return np.concatenate([Rt.T @ f, Rt.T @ tau])

    def _over_limit(self, w: np.ndarray) -> bool:
        force, torque = float(np.linalg.norm(w[:3])), float(np.linalg.norm(w[3:]))
        pk = self.peaks
        pk.force, pk.torque = max(pk.force, force), max(pk.torque, torque)
        pk.lateral_force = max(pk.lateral_force, float(np.hypot(w[0], w[1])))
        if self.task.step != 0.0:
            pk.insert_force = max(pk.insert_force, float(-np.sign(self.task.step) * w[2]))
        if force > self.params.force_limit or torque > self.params.torque_limit:
            self._failure = Finding(FindingCode.CONTACT_FORCE_LIMIT,
                                    f"{self.name}: contact wrench {force:.1f} N / {torque:.2f} N m beyond the "
                                    f"limits {self.params.force_limit:.0f} N / {self.params.torque_limit:.1f} N m")
            return True
        return False

    def _advance(self, w: np.ndarray) -> None:
        task = self.task
        self.elapsed += self.params.period * self.rate
        if self.stopped:
            self.settled += 1
            return
        if task.stop == "time":
            self.stopped = self.elapsed >= task.duration
            return
        opposing = -np.sign(task.step) * w[2]
        if task.stop == "force" and opposing > self.params.insert_force:
            # Hold the insertion axis while the force is above F_tz: on a guide surface the
            # lateral admittance keeps sliding the part in and the force falls again; on the
            # floor it stays and nothing slides, and after `settle_cycles` such cycles the
            # insertion is complete.
            self.above = 0 if self._sliding() else self.above + 1
            if self.above >= task.settle_cycles:
                self.stopped = True
                self._check_seat()
            return
        self.above = 0
        self._lateral_history.clear()
        step = abs(task.step) * self.rate
        if self.travelled + step > task.travel + 1e-12:
            if task.stop == "distance":
                self.travelled = task.travel
                self.stopped = True
            else:
                self._failure = Finding(FindingCode.CONTACT_MISSING, f"{self.name}: no contact force above "
                                        f"{self.params.insert_force} N within {1e3 * task.travel:.0f} mm")
            return
        self.travelled += step

    def _sliding(self) -> bool:
        """The admittance still moves the part sideways: net motion over the last
        `settle_cycles` cycles faster than SLIDE_SPEED (a cycle-to-cycle chatter against a
        wall cancels out)."""
        history = self._lateral_history
        history.append(self.admittance.x[:3][self.impedance_axes[:3]].copy())
        if len(history) < history.maxlen:
            return True
        net = np.abs(history[-1] - history[0])
        return bool(net.size and net.max() > SLIDE_SPEED * (len(history) - 1) * self.params.period)

    def _check_seat(self) -> None:
        task = self.task
        if task.seat_travel is not None and self.travelled < task.seat_travel - task.seat_tolerance:
            self._failure = Finding(FindingCode.JAMMED, f"{self.name}: stopped by {self.params.insert_force} N after "
                                    f"{1e3 * self.travelled:.1f} mm, short of the {1e3 * task.seat_travel:.1f} mm "
                                    f"to the seat (jammed or blocked)")

    def _pose(self, dx: np.ndarray) -> np.ndarray:
        """X_d = X0 (+) dX, with dX in the task frame about the compliance centre (eq. 21)."""
        R0, p0 = self.X0[:3, :3], self.X0[:3, 3]
        c = self.task.compliance_center
        Rt = self.task.task_rotation
        Rd = Rt @ rotvec_to_matrix(dx[3:]) @ Rt.T @ R0
        centre = p0 + R0 @ c + Rt @ dx[:3]
        Xd = np.eye(4)
        Xd[:3, :3] = Rd
        Xd[:3, 3] = centre - Rd @ c
        return Xd

    def _inverse(self, Xd: np.ndarray) -> np.ndarray:
        q = self.q_cmd.copy()
        for _ in range(2):
            T, J = fk_jacobian(self.model, self.data, q)
            e = twist_error(Xd, T)
            q = q + J.T @ np.linalg.solve(J @ J.T + IK_DAMPING ** 2 * np.eye(6), e)
        return q
