"""Read the serial chain between two links of a URDF: joint geometry, limits and inertials.

Only what the arm file needs: the joints from `base` to `tip` (revolute, continuous,
prismatic; fixed joints folded), each with its pose at q = 0 in the base link's frame, and
for each moving joint the rigid body it carries (its child link plus everything attached to
it that is not beyond the next chain joint; joints off the chain are held at q = 0, as
Pinocchio's reduced model does). Errors are `UrdfError`, one line naming file, link or joint.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from spacearm.base.config.errors import ConfigError
from spacearm.base.spatial import xyz_rpy_to_transform

Array = NDArray[np.float64]
MOVING = ("revolute", "continuous", "prismatic")
KNOWN = MOVING + ("fixed", "floating", "planar")


class UrdfError(ConfigError):
    """The URDF cannot give an arm: unreadable, disconnected chain, unsupported joint."""


@dataclass(frozen=True)
class UrdfJoint:
    name: str
    type: str                  # revolute, continuous, prismatic, fixed
    parent: str
    child: str
    origin: Array              # 4x4 parent link -> joint frame
    axis: Array                # unit, in the joint frame
    lower: float | None
    upper: float | None
    velocity: float | None
    effort: float | None


@dataclass(frozen=True)
class Inertial:
    mass: float
    origin: Array              # 4x4 link -> inertial frame
    inertia: Array             # 3x3 about the com, inertial frame axes


@dataclass(frozen=True)
class Body:
    """A rigid body in some frame: mass, com and inertia about the com (that frame's axes)."""
    mass: float
    com: Array
    inertia: Array


@dataclass(frozen=True)
class Chain:
    """The moving joints base -> tip with their poses at q = 0 in the base link frame."""
    path: Path
    base: str
    tip: str
    joints: list[UrdfJoint]        # moving joints only, base to tip
    joint_poses: list[Array]       # world pose of each moving joint's frame at q = 0
    axes: list[Array]              # unit axis of each moving joint in the base frame
    tip_pose: Array                # world pose of the tip link at q = 0
    bodies: list[Body | None]      # per moving joint, in the base frame at q = 0; None = no inertial


def _floats(text: str | None, count: int, default: float, where: str) -> Array:
    if text is None:
        return np.full(count, default)
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        raise UrdfError(f"{where}: not {count} numbers: {text!r}") from None
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise UrdfError(f"{where}: expected {count} finite numbers, got {text!r}")
    return np.array(values)


def _origin(element: ET.Element | None, where: str) -> Array:
    if element is None:
        return np.eye(4)
    return xyz_rpy_to_transform(_floats(element.get("xyz"), 3, 0.0, f"{where} origin xyz"),
                                _floats(element.get("rpy"), 3, 0.0, f"{where} origin rpy"))


def _attr(element: ET.Element | None, name: str, where: str) -> float | None:
    if element is None or element.get(name) is None:
        return None
    return float(_floats(element.get(name), 1, 0.0, f"{where} {name}")[0])


def _parse_joint(element: ET.Element, path: Path) -> UrdfJoint:
    name = element.get("name") or "?"
    where = f"{path}: joint {name!r}"
    kind = element.get("type")
    if kind not in KNOWN:
        raise UrdfError(f"{where}: unknown joint type {kind!r}")
    parent, child = element.find("parent"), element.find("child")
    if parent is None or child is None or not parent.get("link") or not child.get("link"):
        raise UrdfError(f"{where}: needs <parent link=...> and <child link=...>")
    axis_element = element.find("axis")   # URDF default axis: x
    axis = (np.array([1.0, 0.0, 0.0]) if axis_element is None
            else _floats(axis_element.get("xyz"), 3, 0.0, f"{where} axis"))
    if kind in MOVING:
        norm = float(np.linalg.norm(axis))
        if norm < 1e-12:
            raise UrdfError(f"{where}: axis is zero")
        axis = axis / norm
    limit = element.find("limit")
    return UrdfJoint(name=name, type=kind, parent=parent.get("link"), child=child.get("link"),
                     origin=_origin(element.find("origin"), where), axis=axis,
                     lower=_attr(limit, "lower", where), upper=_attr(limit, "upper", where),
                     velocity=_attr(limit, "velocity", where), effort=_attr(limit, "effort", where))


def _parse_inertial(link: ET.Element, path: Path) -> Inertial | None:
    element = link.find("inertial")
    if element is None:
        return None
    where = f"{path}: link {link.get('name')!r} inertial"
    mass = _attr(element.find("mass"), "value", where)
    if mass is None or mass < 0.0:
        raise UrdfError(f"{where}: needs <mass value=...> >= 0")
    names = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    values = [_attr(element.find("inertia"), k, where) or 0.0 for k in names]
    ixx, ixy, ixz, iyy, iyz, izz = values
    inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    return Inertial(mass=mass, origin=_origin(element.find("origin"), where), inertia=inertia)


def merge_bodies(bodies: list[Body]) -> Body:
    """One body from several in the same frame (parallel-axis theorem about the common com)."""
    mass = sum(b.mass for b in bodies)
    if mass <= 0.0:
        return Body(0.0, np.zeros(3), np.zeros((3, 3)))
    com = sum(b.mass * b.com for b in bodies) / mass
    inertia = np.zeros((3, 3))
    for b in bodies:
        r = b.com - com
        inertia += b.inertia + b.mass * (float(r @ r) * np.eye(3) - np.outer(r, r))
    return Body(mass, com, inertia)


def transform_body(body: Body, T: Array) -> Body:
    """The body expressed in another frame: T maps the body's frame into the new one."""
    R = T[:3, :3]
    return Body(body.mass, R @ body.com + T[:3, 3], R @ body.inertia @ R.T)


def read_chain(path: str | Path, base: str, tip: str) -> Chain:
    """Parse `path` and extract the chain base -> tip (see the module doc)."""
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except FileNotFoundError:
        raise UrdfError(f"{path}: file not found") from None
    except OSError as exc:
        raise UrdfError(f"{path}: cannot read: {exc.strerror}") from None
    except ET.ParseError as exc:
        raise UrdfError(f"{path}: not valid XML: {exc}") from None
    if root.tag != "robot":
        raise UrdfError(f"{path}: root element is <{root.tag}>, a URDF has <robot>")
    links = {link.get("name"): link for link in root.findall("link")}
    for name, role in ((base, "base"), (tip, "tip")):
        if name not in links:
            raise UrdfError(f"{path}: {role} link {name!r} is not in the URDF")
    joints = [_parse_joint(j, path) for j in root.findall("joint")]
    by_child = {j.child: j for j in joints}
    chain: list[UrdfJoint] = []
    link = tip
    while link != base:
        joint = by_child.get(link)
        if joint is None:
            raise UrdfError(f"{path}: link {tip!r} is not connected to base {base!r} "
                            f"(walking up from the tip ends at link {link!r})")
        chain.append(joint)
        link = joint.parent
    chain.reverse()
    for joint in chain:
        if joint.type in ("floating", "planar"):
            raise UrdfError(f"{path}: joint {joint.name!r} is {joint.type}; supported: revolute, "
                            "continuous, prismatic, fixed")
    moving = [j for j in chain if j.type in MOVING]
    if not moving:
        raise UrdfError(f"{path}: no revolute, continuous or prismatic joint between {base!r} and {tip!r}")

    # Poses at q = 0 (a joint's motion is identity there, so each child link frame is the
    # joint's frame).
    world = {base: np.eye(4)}
    poses, axes = [], []
    for joint in chain:
        world[joint.child] = world[joint.parent] @ joint.origin
        if joint.type in MOVING:
            poses.append(world[joint.child])
            axes.append(world[joint.child][:3, :3] @ joint.axis)

    # Every link's world pose at q = 0 (off-chain joints held at 0 too), for the inertials.
    children: dict[str, list[UrdfJoint]] = {}
    for joint in joints:
        children.setdefault(joint.parent, []).append(joint)
    chain_moving = {j.name for j in moving}
    inertials = {name: _parse_inertial(el, path) for name, el in links.items()}

    def subtree(start: str, pose: Array) -> list[tuple[str, Array]]:
        """Links rigidly carried by `start` (stops at the next chain joint)."""
        out, stack = [], [(start, pose)]
        while stack:
            name, T = stack.pop()
            out.append((name, T))
            for joint in children.get(name, []):
                if joint.name not in chain_moving:
                    stack.append((joint.child, T @ joint.origin))
        return out

    bodies: list[Body | None] = []
    for joint in moving:
        parts, any_inertial = [], False
        for name, T in subtree(joint.child, world[joint.child]):
            inertial = inertials.get(name)
            if inertial is None:
                continue
            any_inertial = True
            frame = T @ inertial.origin
            parts.append(transform_body(Body(inertial.mass, np.zeros(3), inertial.inertia), frame))
        bodies.append(merge_bodies(parts) if any_inertial else None)
    return Chain(path=path, base=base, tip=tip, joints=moving, joint_poses=poses, axes=axes,
                 tip_pose=world[tip], bodies=bodies)

