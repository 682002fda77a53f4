"""Single contact subtasks on the plant without the bus (DirectLoop): the insertion and
capture trials of the tests and bench/bench_oru.py, with a chosen start error.

The controller side is the task flow's own code: the ContactTask built by
spacearm.controller.oru.flow for subtask 3 (capture) or 9 (insert) and the ImpedanceMode.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from spacearm.base.config.arm import load_arm_config
from spacearm.controller.impedance.config import load_impedance
from spacearm.controller.impedance.mode import ImpedanceMode
from spacearm.base.kinematics import KinematicData, KinematicModel, solve_ik
from spacearm.base.spatial import rotvec_to_matrix
from spacearm.controller.oru.config import load_changeout
from spacearm.controller.oru.flow import FlowContext, contact_step
from spacearm.firmware_sim.contact.config import ContactConfig
from spacearm.offline.contact.direct_loop import DirectLoop
from spacearm.firmware_sim.plant import Plant, load_plant_config

ARM = "configs/arm/oru_testbed_6dof.toml"
PLANT = "configs/oru/plant_cell.toml"
SETTLE_CYCLES = 25


@dataclass
class TrialResult:
    success: bool            # seated (plant truth) and no failure
    failure: str | None
    arm_time: float          # s of control time in the subtask
    wall_time: float
    peak_lateral_force: float
    peak_torque: float
    peak_insert_force: float
    final_lateral_error: float   # m, seated part vs its true seat (plant truth)
    final_angle_error: float     # rad


class ContactTrials:
    def __init__(self, plant_file: str = PLANT, contact: ContactConfig | None = None):
        self.arm = load_arm_config(ARM)
        self.model = KinematicModel.from_config(self.arm)
        self.plant_config = load_plant_config(plant_file)
        if contact is not None:
            self.plant_config = self.plant_config.model_copy(update={"contact": contact})
        self.impedance = load_impedance()
        self.changeout = load_changeout()

    def run(self, kind: str, store: str, lateral: tuple[float, float] = (0.0, 0.0),
            rotvec: tuple[float, float, float] = (0.0, 0.0, 0.0), oru: str = "old_oru",
            max_cycles: int = 3000) -> TrialResult:
        """kind "insert": `oru` held, inserted into `store`; "capture": the adapter of the ORU
        in `store`. The start is the nominal pre-contact pose moved by `lateral` (m, slot x/y)
        and turned by `rotvec` (rad, slot frame, about the part's tip)."""
        plant = Plant.create(self.model.nq, self.plant_config)
        world = plant.environment
        ctx = FlowContext(self.model, None, world.scene, self.changeout, self.impedance, {},
                          np.array(self.arm.postures["ready"]))
        placing = kind == "insert"
        if placing:
            self._hold(world, oru)
            plant.ee.grip = 1.0                 # clamped
            ctx.holding = oru
        # The start error is relative to the true seat (plant truth), so `lateral` and `rotvec`
        # are the whole misalignment the guides must absorb.
        g = world.scene.geometry
        grasp = np.linalg.inv(g.tool_T_oru())
        seat = world.slots[store] @ world.slot_T_oru if placing else world.oru_pose(world.occupant(store))
        slot = world.slots[store]
        start = seat @ grasp
        start[:3, 3] += slot[:3, 2] * ctx.contact_height(placing)
        tip = start @ (ctx.scene.geometry.tool_T_oru() if placing else np.eye(4))
        turn = slot[:3, :3] @ rotvec_to_matrix(rotvec) @ slot[:3, :3].T
        start[:3, :3] = turn @ start[:3, :3]
        start[:3, 3] = tip[:3, 3] + turn @ (start[:3, 3] - tip[:3, 3]) + slot[:3, :2] @ np.asarray(lateral)
        ik = solve_ik(self.model, KinematicData(self.model), start, np.array(self.arm.postures["ready"]))
        if not ik.success:
            raise ValueError(f"start pose unreachable: {ik.message}")
        loop = DirectLoop(plant, self.impedance.period)
        loop.set_position(ik.q)
        for _ in range(SETTLE_CYCLES):         # let the servos take up the load before the tare
            loop.command(ik.q)
            plant.step(loop.period)
        step = contact_step(ctx, 0, 9 if placing else 3, store, kind)
        step.begin(ik.q, 0.0)
        mode: ImpedanceMode = step.mode
        wall = time.perf_counter()
        cycles = 0
        out = None
        while cycles < max_cycles and (out is None or (out.failure is None and not out.finished)):
            out = loop.cycle(step)
            cycles += 1
        wall = time.perf_counter() - wall
        lateral_err, angle_err, seated = self._seat_error(world, placing, oru, store)
        failure = out.failure if out is not None else None
        return TrialResult(failure is None and out is not None and out.finished and seated,
                           None if failure is None else failure.message, loop.time, wall,
                           mode.peaks.lateral_force, mode.peaks.torque, mode.peaks.insert_force,
                           lateral_err, angle_err)

    @staticmethod
    def _hold(world, oru: str) -> None:
        o = world.orus[oru]
        world.latched[o.store] = False
        o.where, o.store = "tool", None
        world.grasped = oru
        world.tool_T_oru = world.scene.geometry.tool_T_oru()

    @staticmethod
    def _seat_error(world, placing: bool, oru: str, store: str) -> tuple[float, float, bool]:
        """Lateral and tilt error of the part against its true seat, and whether it is seated
        (plant truth): the ORU on its slot floor, or the adapter captured by the guides."""
        if placing:
            rel = np.linalg.inv(world.slots[store] @ world.slot_T_oru) @ world.oru_pose(oru)
        else:
            occupant = world.occupant(store) or world.grasped
            rel = np.linalg.inv(world.tool_pose) @ world.oru_pose(occupant) @ world.oru_tip
        lateral = float(np.hypot(rel[0, 3], rel[1, 3]))
        angle = float(np.arccos(np.clip(rel[2, 2], -1.0, 1.0)))
        if placing:
            return lateral, angle, abs(rel[2, 3]) < 1.1e-3 and lateral < 1.5e-3
        return lateral, angle, world.captured is not None


@dataclass
class StiffnessResult:
    displacement: np.ndarray     # m, true tool displacement (base x, y, z) at the end
    force: float                 # N applied along base x at the end
    expected: float              # m, force / K


def stiffness_task(gravity, sensor_offset: float, stiffness: float = 1000.0, damping: float = 50.0,
                   duration: float = 10.0):
    """The paper's Section 5.2 experiment: impedance on base x (K = 1 N/mm, B = 50 N s/m),
    position control on the other axes."""
    from spacearm.controller.impedance.mode import ContactTask
    return ContactTask("stiffness experiment", np.eye(3), ("impedance", "hold", "hold", "hold", "hold", "hold"),
                       gravity, sensor_offset, stop="time", duration=duration,
                       stiffness=(stiffness, 1000.0, 1000.0, 20.0, 20.0, 20.0),
                       damping=(damping, 500.0, 500.0, 10.0, 10.0, 10.0))


def force_ramp(t: float, peak: float = 5.0, ramp: float = 5.0) -> float:
    """External force of the experiment: 0 -> peak over `ramp` s, then held."""
    return peak * min(1.0, max(0.0, t) / ramp)


def run_stiffness_direct(trials: ContactTrials, peak: float = 5.0, duration: float = 10.0) -> StiffnessResult:
    from spacearm.controller.impedance.gravity import GravityModel
    plant = Plant.create(trials.model.nq, trials.plant_config)
    loop = DirectLoop(plant, trials.impedance.period)
    q = np.array(trials.arm.postures["ready"])
    loop.set_position(q)
    for _ in range(SETTLE_CYCLES):
        loop.command(q)
        plant.step(loop.period)
    ee = trials.changeout.end_effector
    task = stiffness_task(GravityModel(ee.mass, np.asarray(ee.centroid)), ee.sensor_offset, duration=duration)
    mode = ImpedanceMode(trials.model, trials.impedance, task, q)
    start = plant.tool_pose()[:3, 3].copy()
    t0 = task.tare_cycles * loop.period
    finished = False
    while not finished:
        plant.environment.applied_wrench[0] = force_ramp(loop.time - t0, peak)
        finished = loop.cycle(mode).finished
    return StiffnessResult(plant.tool_pose()[:3, 3] - start, float(plant.environment.applied_wrench[0]),
                           float(plant.environment.applied_wrench[0]) / 1000.0)
