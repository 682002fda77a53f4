"""The plant and a controller Mode in one loop without the CAN bus, for fast tests and the
randomised-insertion benchmark.

Same code on both sides as over the bus: the drives' servo law (`servo_torque`, CSP targets
interpolated over the period as the CiA 402 node does), the plant with its contact world,
the F/T sensor's count quantisation, and the controller's Mode (impedance, ORU subtasks).
What is left out is the CANopen transport itself (PDO timing is lockstep: the measurement of
cycle k is the state after the command of cycle k-1, as on the bus).
"""
from __future__ import annotations

import numpy as np

from spacearm.controller.cycle import Measurement, Mode, ModeOutput
from spacearm.firmware_sim.joint_drive import servo_torque
from spacearm.firmware_sim.plant import Plant

FORCE_COUNTS_PER_N = 100       # spacearm.base.config.bus.FtSettings defaults
TORQUE_COUNTS_PER_NM = 1000


class DirectLoop:
    def __init__(self, plant: Plant, period: float = 0.02):
        self.plant = plant
        self.period = period
        self.time = 0.0
        # The servo's targets as floats: numpy scalars would carry into the joint state and make
        # every sub-step's arithmetic numpy's (the same values, several times slower).
        self.q_start = plant.q_link.tolist()
        self.q_end = list(self.q_start)
        self.v_ff = [0.0] * len(plant.joints)
        for i, joint in enumerate(plant.joints):
            joint.brake_engaged = False
            joint.controller = self._servo(i)

    def _servo(self, i: int):
        joint = self.plant.joints[i]

        def control(s: float, q_meas: float, qd: float) -> float:
            q_ref = self.q_start[i] + s * (self.q_end[i] - self.q_start[i])
            return servo_torque(joint, q_ref, self.v_ff[i], q_meas, qd)
        return control

    def set_position(self, q: np.ndarray) -> None:
        """Teleport the arm (test set-up): joints at rest at q, targets there too."""
        for joint, value in zip(self.plant.joints, q):
            joint.q = joint.theta = float(value)
            joint.qd = joint.thetad = 0.0
        self.q_start = np.array(q, float).tolist()
        self.q_end = list(self.q_start)
        if self.plant.environment is not None:
            self.plant.environment.step(self.plant, 0.0)   # the sensor reads the new pose at once

    def measure(self) -> Measurement:
        joints = self.plant.joints
        raw = np.array(self.plant.ft_reading())
        scale = np.array([FORCE_COUNTS_PER_N] * 3 + [TORQUE_COUNTS_PER_NM] * 3, float)
        n = len(joints)
        return Measurement(time=self.time, sync_counter=0,
                           q=np.array([j.q_measured for j in joints]), dq=np.array([j.qd for j in joints]),
                           tau=np.zeros(n), joints_enabled=np.ones(n, bool), joints_faulted=np.zeros(n, bool),
                           wrench=np.round(raw * scale) / scale)

    def command(self, q: np.ndarray, dq: np.ndarray | None = None) -> None:
        self.q_start, self.q_end = self.q_end, np.asarray(q, float).tolist()
        self.v_ff = [0.0] * len(self.q_end) if dq is None else np.asarray(dq, float).tolist()

    def cycle(self, mode: Mode) -> ModeOutput:
        """One read-update-write cycle of `mode` against the plant; the mode's output."""
        out = mode.update(self.time, self.measure())
        self.command(out.setpoint.q, out.setpoint.dq)
        self.plant.step(self.period)
        self.time += self.period
        return out
