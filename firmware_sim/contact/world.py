"""The ORU cell as the plant's `Environment`: what the arm touches and carries.

Every physics sub-step (after the joints moved) it poses the tool from the true arm
geometry, evaluates the two contacts of the cell (adapter head in the end-effector guide
blocks, held ORU in a store slot; see cavity.py), the clamp of a grasped adapter whose ORU
is still latched in its store, gravity of the end effector and of a carried ORU, and an
optional applied wrench (tests: the paper's stiffness experiment). The sum is written to
`plant.wrench` (force ON the end effector, sensor frame, about the sensor origin) and, as
tau = -J^T W, to each joint's `external_torque`.

Mechanisms: the end effector's grip closing on a captured adapter grasps the ORU (and sets
the end effector's `target_present`, so its lock only seats on a real adapter); the store
latch (`drive_latch`, driven through the end effector's screw drive) takes `latch_time`
to open or close and holds the ORU in its slot.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from spacearm.base.config.scene import SceneConfig, load_scene
from spacearm.base.kinematics.jacobian import fk_jacobian
from spacearm.base.kinematics.model import KinematicData, KinematicModel
from spacearm.base.kinematics.pose_error import twist_error
from spacearm.base.spatial import cross3
from spacearm.firmware_sim.contact.cavity import Cavity, ContactLaw, MaleBox, box_contact, may_touch
from spacearm.firmware_sim.contact.config import ContactConfig

CAPTURE_LATERAL = 1.0e-3     # m beyond the guide clearance still counted as captured
CAPTURE_DEPTH = 1.5e-3       # m short of the guide floor still counted as captured
CAPTURE_ANGLE = math.radians(2.0)
SEATED_HEIGHT = 3.0e-3       # m above the slot floor a released ORU counts as seated


@dataclass
class OruBody:
    name: str
    mass: float
    centroid_height: float
    pose: np.ndarray              # base_T_oru while in a store or loose
    where: str = "store"          # "store" | "tool" | "loose"
    store: str | None = None


@dataclass
class LatchOperation:
    store: str
    lock: bool
    remaining: float


@dataclass
class WorldStats:
    """Peaks since the last reset, for tests and benchmarks (plant truth)."""
    peak_force: float = 0.0
    peak_torque: float = 0.0
    contact_force: np.ndarray = field(default_factory=lambda: np.zeros(3))


class ContactWorld:
    def __init__(self, config: ContactConfig, model: KinematicModel, scene: SceneConfig | None = None):
        self.config = config
        self.model = model
        self.data = KinematicData(model)
        self.scene = (scene or load_scene(config.scene_path())).with_true_offsets(config.store_offsets)
        g = self.scene.geometry
        self.law = ContactLaw(config.stiffness, config.damping, config.friction, config.slip_velocity)
        self.oru_box = MaleBox(g.oru_size[0] / 2, g.oru_size[1] / 2, g.oru_size[2])
        self.adapter_box = MaleBox(g.adapter_size[0] / 2, g.adapter_size[1] / 2, g.adapter_size[2])
        self.slot = Cavity(self.oru_box.half_x + g.slot_clearance, self.oru_box.half_y + g.slot_clearance,
                           g.slot_chamfer, g.slot_depth)
        self.closed_slot = Cavity(self.slot.half_x, self.slot.half_y, g.slot_chamfer, 0.0)
        self.guide = Cavity(self.adapter_box.half_x + g.guide_clearance, self.adapter_box.half_y + g.guide_clearance,
                            g.guide_chamfer, g.guide_depth)
        self.oru_tip = g.oru_tip()
        self.slot_T_oru = g.slot_T_oru()
        self.slots = {s.name: s.pose.matrix() @ s.true_offset.matrix() for s in self.scene.stores}
        self._slot_inverse = {name: _rigid_inverse(slot) for name, slot in self.slots.items()}
        self._slot_origin = {name: slot[:3, 3] for name, slot in self.slots.items()}
        # Beyond this distance between an ORU's origin and a slot's, they cannot touch.
        self._slot_reach = float(np.hypot(self.slot.half_x + self.slot.chamfer + self.slot.rim,
                                          self.slot.half_y + self.slot.chamfer + self.slot.rim)
                                 + np.linalg.norm(g.oru_size) + 0.02)
        self.latched = {s.name: s.holds is not None for s in self.scene.stores}
        self.orus: dict[str, OruBody] = {}
        for s in self.scene.stores:
            if s.holds is not None:
                o = self.scene.oru(s.holds)
                self.orus[o.name] = OruBody(o.name, o.mass, o.centroid_height,
                                            self.slots[s.name] @ self.slot_T_oru, "store", s.name)
        self.grasped: str | None = None
        self.tool_T_oru = np.eye(4)
        self.captured: str | None = None
        self.latch_op: LatchOperation | None = None
        self.latch_jammed = False                  # fault injection: the latch never moves
        self.applied_wrench = np.zeros(6)          # base frame, force on the tool and torque about it
        self.applied_profile = None                # optional f(plant time) -> applied_wrench (tests)
        self.stats = WorldStats()
        self._ee_centroid = np.asarray(config.ee_centroid, float)
        self.tool_pose = np.eye(4)
        self._previous: dict[str, np.ndarray] = {}
        self._tips: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self._centroids: dict[str, np.ndarray] = {}
        self._near = True
        self._pose_time = -1.0
        self._J: np.ndarray | None = None

    # ---- queries ---------------------------------------------------------------------
    def occupant(self, store: str) -> str | None:
        for o in self.orus.values():
            if o.where == "store" and o.store == store:
                return o.name
        return None

    def oru_pose(self, name: str) -> np.ndarray:
        o = self.orus[name]
        return self.tool_pose @ self.tool_T_oru if o.where == "tool" else o.pose

    # ---- mechanisms ------------------------------------------------------------------
    def drive_latch(self, lock: bool) -> bool:
        """Start opening/closing the latch of the store the grasped ORU is in (or seated in)."""
        if self.grasped is None or self.latch_op is not None:
            return False
        store = self._store_of_grasped()
        if store is None:
            return False
        self.latch_op = LatchOperation(store, lock, self.config.latch_time)
        return True

    def _store_of_grasped(self) -> str | None:
        o = self.orus[self.grasped]
        if o.where == "store":
            return o.store
        return self._seated_slot(self.oru_pose(o.name))

    def _seated_slot(self, base_T_oru: np.ndarray) -> str | None:
        for name, slot in self.slots.items():
            rel = np.linalg.inv(slot @ self.slot_T_oru) @ base_T_oru
            if (np.abs(rel[:3, 3]) < (self.slot.half_x, self.slot.half_y, SEATED_HEIGHT)).all() \
                    and rel[2, 2] > math.cos(CAPTURE_ANGLE) and self.occupant(name) is None:
                return name
        return None

    def _advance_latch(self, h: float) -> None:
        op = self.latch_op
        if op is None or self.latch_jammed:
            return
        op.remaining -= h
        if op.remaining > 0.0:
            return
        self.latch_op = None
        self.latched[op.store] = op.lock
        if self.grasped is None:
            return
        o = self.orus[self.grasped]
        if op.lock and o.where == "tool":
            # Latched where it is (no snap to the nominal seat: the grip would feel it as a jump).
            o.where, o.store, o.pose = "store", op.store, self.tool_pose @ self.tool_T_oru
        elif not op.lock and o.where == "store" and o.store == op.store:
            o.where, o.store = "tool", None

    def _update_grip(self, plant) -> None:
        ee = plant.ee
        if ee is None:
            return
        if self.grasped is None and ee.grip >= 1.0 and self.captured is not None:
            o = self.orus[self.captured]
            self.grasped = o.name
            self.tool_T_oru = np.linalg.inv(self.tool_pose) @ o.pose
            if not self.latched.get(o.store or "", False):
                o.where, o.store = "tool", None
        elif self.grasped is not None and ee.grip < 1.0:
            o = self.orus[self.grasped]
            if o.where == "tool":
                pose = self.tool_pose @ self.tool_T_oru
                store = self._seated_slot(pose)
                if store is not None:
                    o.where, o.store, o.pose = "store", store, pose
                else:
                    o.where, o.store, o.pose = "loose", None, pose   # dropped
            self.grasped = None
        present = self.grasped is not None or self.captured is not None
        if ee.params.target_present != present:
            ee.params = ee.params.model_copy(update={"target_present": present})

    # ---- the Environment protocol ----------------------------------------------------
    def step(self, plant, h: float) -> None:
        # Far from every contact only gravity acts: the pose and Jacobian of the period's first
        # sub-step serve the rest of it (the tool moves < 1 mm in 20 ms), a tenth of the cost.
        if self._near or plant.time != self._pose_time or self._J is None or h <= 0.0:
            q = np.fromiter((j.q for j in plant.joints), float, len(plant.joints))
            T, J = fk_jacobian(self.model, self.data, q)
            self._J, self._pose_time = J.copy(), plant.time
            self.tool_pose = T.copy()
        T, J = self.tool_pose, self._J
        near = False
        if self.applied_profile is not None:
            self.applied_wrench = np.asarray(self.applied_profile(plant.time), float)
        p_tool, R_tool = T[:3, 3], T[:3, :3]
        # The sums in scalars, each component the same additions in the same order as numpy's
        # 3-vectors (issue 35: the arrays' calls were a third of a contact sub-step).
        w = self.applied_wrench.tolist()
        force, torque, contact = w[:3], w[3:], [0.0, 0.0, 0.0]

        def add(points_b: np.ndarray, forces_b: np.ndarray) -> None:
            total = forces_b.sum(axis=0).tolist()
            force[:] = _plus(force, total)
            torque[:] = _plus(torque, _cross_sum(points_b - p_tool, forces_b).tolist())
            contact[:] = _plus(contact, total)

        def add_weight(point_b: np.ndarray, weight: float) -> None:
            # add() of one point's force (0, 0, -weight) without its (1, 3) arrays: the same sums.
            f = [0.0, 0.0, -weight]
            force[:] = _plus(force, f)
            torque[:] = _plus(torque, cross3((point_b - p_tool).tolist(), f))

        self.captured = None
        tool_T_base = None
        for o in self.orus.values():
            if o.name == self.grasped:
                continue
            tip = self._tip(o)
            if _distance(tip[:3, 3], p_tool) > self.config.near:
                self._previous.pop("guide:" + o.name, None)
                continue
            near = True
            if tool_T_base is None:
                tool_T_base = _rigid_inverse(T)
            F_T_M = tool_T_base @ tip
            previous = self._moved("guide:" + o.name, F_T_M)
            if may_touch(self.guide, self.adapter_box, F_T_M):
                p, f = box_contact(self.guide, self.adapter_box, self.law, F_T_M, _rate(F_T_M, previous, h))
                # Zero forces add nothing (the sums start at +0.0, and adding +-0.0 keeps them).
                if f.any():
                    add(p @ R_tool.T + p_tool, -(f @ R_tool.T))     # reaction on the end effector
            if self._is_captured(F_T_M):
                self.captured = o.name
        if self.grasped is not None:
            o = self.orus[self.grasped]
            if o.where == "tool":
                base_T_oru = T @ self.tool_T_oru
                origin = base_T_oru[:3, 3]
                for name, slot in self.slots.items():
                    key = "slot:" + name
                    if _distance(origin, self._slot_origin[name]) > self._slot_reach:
                        self._previous.pop(key, None)
                        continue
                    near = True
                    cavity = self.slot if self.occupant(name) is None else self.closed_slot
                    F_T_M = self._slot_inverse[name] @ base_T_oru
                    previous = self._moved(key, F_T_M)
                    if not may_touch(cavity, self.oru_box, F_T_M):
                        continue
                    p, f = box_contact(cavity, self.oru_box, self.law, F_T_M, _rate(F_T_M, previous, h))
                    if f.any():
                        add(p @ slot[:3, :3].T + slot[:3, 3], f @ slot[:3, :3].T)
                if self.config.gravity > 0.0:
                    c = base_T_oru @ self._centroid(o)
                    add_weight(c[:3], o.mass * self.config.gravity)
            else:
                near = True
                # Clamped on an adapter whose ORU the store still holds: a stiff spring.
                err = twist_error(o.pose @ np.linalg.inv(self.tool_T_oru), T)
                f = (self.config.grasp_stiffness * err[:3]).tolist()
                force[:] = _plus(force, f)
                torque[:] = _plus(torque, (self.config.grasp_rot_stiffness * err[3:]).tolist())
                contact[:] = _plus(contact, f)
        sensor_origin = p_tool - self.config.sensor_offset * R_tool[:, 2]
        if self.config.gravity > 0.0 and self.config.ee_mass > 0.0:
            add_weight(sensor_origin + R_tool @ self._ee_centroid, self.config.ee_mass * self.config.gravity)
        tau = (J.T @ np.array(force + torque)).tolist()
        for joint, t in zip(plant.joints, tau):
            joint.external_torque = -t
        torque_at_sensor = _plus(torque, cross3((p_tool - sensor_origin).tolist(), force))
        plant.wrench[:3] = (R_tool.T @ np.array(force)).tolist()
        plant.wrench[3:] = (R_tool.T @ np.array(torque_at_sensor)).tolist()
        self._near = near
        self.stats.contact_force = np.array(contact)
        self.stats.peak_force = max(self.stats.peak_force, _distance(self.stats.contact_force, 0.0))
        self._update_grip(plant)
        self._advance_latch(h)

    def _moved(self, key: str, F_T_M: np.ndarray) -> np.ndarray | None:
        """The contact's pose one sub-step ago (None: not evaluated then); F_T_M from now on."""
        previous = self._previous.get(key)
        self._previous[key] = F_T_M
        return previous

    def _tip(self, o: OruBody) -> np.ndarray:
        """base_T_tip of an ORU's adapter, kept while its pose (replaced, never written) stays."""
        kept = self._tips.get(o.name)
        if kept is None or kept[0] is not o.pose:
            kept = self._tips[o.name] = (o.pose, o.pose @ self.oru_tip)
        return kept[1]

    def _centroid(self, o: OruBody) -> np.ndarray:
        c = self._centroids.get(o.name)
        if c is None:
            c = self._centroids[o.name] = np.array([0.0, 0.0, o.centroid_height, 1.0])
        return c

    def _is_captured(self, F_T_M: np.ndarray) -> bool:
        x, y, z = F_T_M[:3, 3]
        return (abs(x) < self.guide.half_x - self.adapter_box.half_x + CAPTURE_LATERAL
                and abs(y) < self.guide.half_y - self.adapter_box.half_y + CAPTURE_LATERAL
                and z < -(self.guide.depth - CAPTURE_DEPTH)
                and F_T_M[2, 2] > math.cos(CAPTURE_ANGLE))


def _rate(F_T_M: np.ndarray, previous: np.ndarray | None, h: float) -> np.ndarray:
    return np.zeros((4, 4)) if previous is None or h <= 0.0 else (F_T_M - previous) / h


def _plus(a: list[float], b: list[float]) -> list[float]:
    return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]


def _rigid_inverse(T: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def _distance(a: np.ndarray, b) -> float:
    """|a - b| for 3-vectors: np.linalg.norm's own sum (sqrt of the dot product), without its checks."""
    d = a - b
    return math.sqrt(d.dot(d))


def _cross_sum(r: np.ndarray, f: np.ndarray) -> np.ndarray:
    """sum_i r_i x f_i for (n, 3) arrays (np.cross costs ~40 us a call here)."""
    rx, ry, rz = r[:, 0], r[:, 1], r[:, 2]
    fx, fy, fz = f[:, 0], f[:, 1], f[:, 2]
    return np.array([(ry * fz - rz * fy).sum(), (rz * fx - rx * fz).sum(), (rx * fy - ry * fx).sum()])


def build_contact_world(config: ContactConfig, plant) -> ContactWorld:
    return ContactWorld(config, plant.true_model)
