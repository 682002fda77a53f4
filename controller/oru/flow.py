"""The ORU changeout as a list of steps: the paper's Table 1 for each pair of stages.

Stage 2k (extracting, subtasks 1-6) takes the ORU out of its store; stage 2k+1 (inserting,
subtasks 7-13) puts it into its store and returns to the initial pose. Target poses come
from the cell file's nominal store poses and the ORU/adapter geometry; the closed-loop
approach (subtasks 2 and 8) is the registry's "approach" mode when there is one.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from spacearm.base.config.scene import SceneConfig
from spacearm.controller.cycle import EndEffectorCommand, EndEffectorState, FindingCode, Mode
from spacearm.controller.modes import PlannedMode
from spacearm.controller.impedance.config import ImpedanceParams
from spacearm.controller.impedance.gravity import GravityModel
from spacearm.controller.impedance.mode import ContactTask
from spacearm.base.kinematics.inverse import solve_ik
from spacearm.base.kinematics.model import KinematicData, KinematicModel
from spacearm.controller.oru.config import ChangeoutConfig
from spacearm.controller.oru.linear_move import LinearToolMove
from spacearm.controller.oru.steps import ContactStep, EndEffectorStep, LatchStep, ModeStep, Step

TABLE_1 = {
    1: ("gets close to the ORU", "open loop path planning"),
    2: ("approaches the ORU adapter", "close loop path planning"),
    3: ("captures the adapter completely", "impedance control"),
    4: ("end effector locks the adapter", "-"),
    5: ("ORU connection mechanism unlocks", "-"),
    6: ("pulls the ORU out of the store", "impedance control"),
    7: ("moves the ORU to the top of the store", "open loop path planning"),
    8: ("approaches the store with the ORU", "close loop path planning"),
    9: ("inserts the ORU", "impedance control"),
    10: ("ORU connection mechanism locks", "-"),
    11: ("end effector unlocks the adapter", "-"),
    12: ("withdraws to the top of the adapter", "impedance control"),
    13: ("backs to the initial pose", "open loop path planning"),
}
STEP_AXES = ("impedance", "impedance", "step", "impedance", "impedance", "impedance")
# the camera's failures in the closed-loop approach: retried, then the flow pauses (runner.py)
VISION_CODES = frozenset({FindingCode.VISION_LOST, FindingCode.CAMERA_STOPPED, FindingCode.FRAME_STALE})


@dataclass
class FlowContext:
    model: KinematicModel
    planner: object                      # spacearm.controller.planning.MotionPlanner
    scene: SceneConfig
    config: ChangeoutConfig
    impedance: ImpedanceParams
    factories: dict[str, Callable[..., Mode]]
    q_initial: np.ndarray
    holding: str | None = None           # ORU in the end effector (controller's belief)
    ft_bias: np.ndarray = field(default_factory=lambda: np.zeros(6))
    notes: list[str] = field(default_factory=list)

    # ---- poses -----------------------------------------------------------------------
    def slot(self, store: str) -> np.ndarray:
        return self.scene.store(store).pose.matrix()

    def above(self, store: str, height: float) -> np.ndarray:
        """The fully seated/captured tool pose of `store`, raised `height` along the slot's z."""
        slot = self.slot(store)
        T = self.scene.geometry.seated_tool_pose(slot)
        T[:3, 3] += slot[:3, 2] * height
        return T

    def gap(self) -> float:
        """Gap between the parts at the handover to contact: wider after the closed-loop
        approach, whose camera must still see the whole marker there."""
        m = self.config.motion
        return m.approach_gap if "approach" in self.factories else m.contact_gap

    def contact_height(self, placing: bool) -> float:
        g = self.scene.geometry
        return (g.slot_depth if placing else g.guide_depth) + self.gap()

    # ---- the end effector's mass properties (eq. 14) ---------------------------------
    def gravity(self) -> GravityModel:
        ee = self.config.end_effector
        model = GravityModel(ee.mass, np.asarray(ee.centroid, float))
        if self.holding is None:
            return model
        oru = self.scene.oru(self.holding)
        sensor_T_tool = np.eye(4)
        sensor_T_tool[2, 3] = ee.sensor_offset
        c = sensor_T_tool @ self.scene.geometry.tool_T_oru() @ np.array([0.0, 0.0, oru.centroid_height, 1.0])
        return model.with_payload(oru.mass, c[:3])

    def compliance_center(self) -> np.ndarray:
        if self.holding is None:
            return np.zeros(3)
        return self.scene.geometry.tool_T_oru()[:3, 3].copy()   # the ORU's bottom face centre


def _joint_move_to(ctx: FlowContext, target: np.ndarray | None, q_goal: np.ndarray | None = None):
    def plan(q0: np.ndarray):
        goal = q_goal
        if goal is None:
            result = solve_ik(ctx.model, KinematicData(ctx.model), target, q0)
            if not result.success:
                raise ValueError(f"no IK solution for the free-motion target: {result.message}")
            goal = result.q
        return ctx.planner.joint_move(q0, goal, ctx.config.motion.speed)
    return plan


def _planned(name: str) -> Callable[[object, float], Mode]:
    return lambda plan, t: PlannedMode(name, plan, t, name)


def _approach_step(ctx: FlowContext, stage: int, number: int, store: str, placing: bool) -> ModeStep:
    title, algorithm = TABLE_1[number]
    dz = ctx.contact_height(placing)
    factory = ctx.factories.get("approach")
    if factory is not None:
        # the approach mode's dz: above the adapter's top face (capturing) or above the held
        # ORU's seated pose (placing); the same pre-contact pose as ctx.above(store, dz)
        dz_mode = dz if placing else ctx.gap()
        return ModeStep(stage, number, title, algorithm, retry_codes=VISION_CODES,
                        make=lambda q0: factory(target=store, dz=dz_mode, holding=ctx.holding))
    target = ctx.above(store, dz)
    limits = ctx.planner.cartesian
    speed = ctx.config.motion.speed
    step = ModeStep(stage, number, title, "open loop (fallback: no closed-loop approach registered)",
                    make=lambda q0: LinearToolMove(ctx.model, q0, target, ctx.impedance.period,
                                                   limits.linear_velocity * speed, limits.angular_velocity * speed,
                                                   "approach (open loop)"))
    step.notes.append("closed-loop approach not available: open-loop Cartesian move to the nominal "
                      "pre-contact pose; the guides absorb the remaining error")
    return step


def contact_step(ctx: FlowContext, stage: int, number: int, store: str, kind: str) -> ContactStep:
    title, algorithm = TABLE_1[number]
    g = ctx.scene.geometry
    gap = ctx.gap()
    imp = ctx.impedance

    def task() -> ContactTask:
        rotation = ctx.slot(store)[:3, :3]
        common = dict(task_rotation=rotation, axes=STEP_AXES, gravity=ctx.gravity(),
                      sensor_offset=ctx.config.end_effector.sensor_offset,
                      compliance_center=ctx.compliance_center())
        if kind in ("capture", "insert"):
            depth = g.guide_depth if kind == "capture" else g.slot_depth
            return ContactTask(kind, step=-imp.step, stop="force", travel=gap + depth + 0.01,
                               seat_travel=gap + depth, seat_tolerance=ctx.config.contact.seat_tolerance,
                               stiffness=ctx.config.contact.capture_stiffness, **common)
        distance = (g.slot_depth + ctx.config.motion.extract_clearance if kind == "extract"
                    else g.guide_depth + ctx.config.motion.withdraw_clearance)
        return ContactTask(kind, step=imp.retract_step, stop="distance", travel=distance, tare_cycles=0,
                           bias=ctx.ft_bias, **common)
    return ContactStep(stage, number, title, algorithm, model=ctx.model, params=imp, task_of=task)


def stage_steps(ctx: FlowContext, stage: int, store: str) -> list[Step]:
    """Subtasks 1-6 (even stage: extracting from `store`) or 7-13 (odd: inserting into it)."""
    ee = ctx.config.end_effector
    view = ctx.config.motion.view_height

    def t(n: int) -> tuple[int, int, str, str]:
        return (stage, n, *TABLE_1[n])

    if stage % 2 == 0:
        return [
            ModeStep(*t(1), background=True, wrap=_planned("free motion"),
                     make=lambda q0: _joint_move_to(ctx, ctx.above(store, ctx.contact_height(False) + view))(q0)),
            _approach_step(ctx, stage, 2, store, placing=False),
            contact_step(ctx, stage, 3, store, "capture"),
            EndEffectorStep(*t(4), command=EndEffectorCommand.CLAMP, expect=EndEffectorState.LOCKED, timeout=ee.clamp_timeout),
            LatchStep(*t(5), command=EndEffectorCommand.LATCH_UNLOCK, wait=ee.latch_wait),
            contact_step(ctx, stage, 6, store, "extract"),
        ]
    return [
        ModeStep(*t(7), background=True, wrap=_planned("free motion"),
                 make=lambda q0: _joint_move_to(ctx, ctx.above(store, ctx.contact_height(True) + view))(q0)),
        _approach_step(ctx, stage, 8, store, placing=True),
        contact_step(ctx, stage, 9, store, "insert"),
        LatchStep(*t(10), command=EndEffectorCommand.LATCH_LOCK, wait=ee.latch_wait),
        EndEffectorStep(*t(11), command=EndEffectorCommand.RELEASE, expect=EndEffectorState.OPEN, timeout=ee.release_timeout),
        contact_step(ctx, stage, 12, store, "withdraw"),
        ModeStep(*t(13), background=True, wrap=_planned("free motion"),
                 make=lambda q0: _joint_move_to(ctx, None, ctx.q_initial)(q0)),
    ]
