"""Schema of the work-cell scene (configs/scene/*.toml): ORU stores, ORUs and their markers.

One file is the single description of the cell for every part that needs it: the plant's
contact world and camera renderer (true poses), the controller's task flow and closed-loop
approach (nominal poses, corrected by vision), and the browser console's 3-D scene.
Poses are parent_T_child = Trans(xyz) * Rz(yaw) Ry(pitch) Rx(roll), SI units.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from pydantic import Field, model_validator

from spacearm.base.paths import CONFIGS
from spacearm.base.config.loader import StrictModel, load_toml_model
from spacearm.base.spatial import xyz_rpy_to_transform

DEFAULT_SCENE = CONFIGS / "scene" / "oru_testbed.toml"


class ScenePose(StrictModel):
    xyz: tuple[float, float, float] = Field(description="m")
    rpy: tuple[float, float, float] = Field(default=(0.0, 0.0, 0.0), description="rad")

    @model_validator(mode="after")
    def _plausible(self) -> "ScenePose":
        if max(abs(v) for v in self.xyz) > 20.0:
            raise ValueError(f"xyz {self.xyz} beyond 20 m: mm given instead of m?")
        if max(abs(v) for v in self.rpy) > 7.0:
            raise ValueError(f"rpy {self.rpy} beyond 2 pi: degrees given instead of rad?")
        return self

    def matrix(self) -> np.ndarray:
        return xyz_rpy_to_transform(self.xyz, self.rpy)


class Store(StrictModel):
    """An ORU store slot. Slot frame: origin at the centre of the slot opening, z out of the
    slot (the insertion direction is -z), x along the ORU's 120 mm side."""
    name: str = Field(min_length=1, max_length=64)
    pose: ScenePose                                   # base_T_slot, nominal (what the controller knows)
    true_offset: ScenePose = ScenePose(xyz=(0.0, 0.0, 0.0))  # slot_nominal_T_slot_true, plant only
    holds: str | None = Field(default=None, description="name of the ORU inside at the start")
    description: str = ""


class Oru(StrictModel):
    name: str = Field(min_length=1, max_length=64)
    mass: float = Field(default=2.0, gt=0.0, le=500.0, description="kg")
    centroid_height: float = Field(default=0.05, ge=0.0, le=2.0, description="m above the ORU's bottom face")


class CellGeometry(StrictModel):
    """Nominal shapes of the ORU, its adapter, the store slot and the end-effector guide
    blocks (ORU paper Section 3.3, Figure 9). ORU frame: origin at the centre of the bottom
    face, z up through the adapter. The same numbers drive the plant's contact world and the
    controller's target poses."""
    oru_size: tuple[float, float, float] = Field(default=(0.12, 0.08, 0.10), description="m: x, y, height")
    adapter_size: tuple[float, float, float] = Field(
        default=(0.04, 0.02, 0.03), description="m: head x, y and its height above the ORU top")
    slot_clearance: float = Field(default=0.0005, gt=0.0, le=0.01, description="m per side (small gap)")
    slot_chamfer: float = Field(default=0.010, ge=0.0, le=0.05, description="m, 45 deg guide at the opening")
    slot_depth: float = Field(default=0.04, gt=0.0, le=1.0, description="m of the ORU inside its slot when seated")
    guide_clearance: float = Field(default=0.0005, gt=0.0, le=0.01, description="m per side, adapter in the guide blocks")
    guide_chamfer: float = Field(default=0.012, ge=0.0, le=0.05,
                                 description="m, arc guide of the end-effector blocks: capture tolerance > 10 mm")
    guide_depth: float = Field(default=0.025, gt=0.0, le=0.2,
                               description="m of adapter head inside the end effector when captured")

    def oru_tip(self) -> np.ndarray:
        """oru_T_tip: the adapter's top face centre, z pointing down into the ORU (the
        direction the adapter enters the end effector)."""
        T = np.diag([1.0, -1.0, -1.0, 1.0])
        T[2, 3] = self.oru_size[2] + self.adapter_size[2]
        return T

    def tool_T_oru(self) -> np.ndarray:
        """Where a fully captured ORU sits in the tool frame (tool z points at the ORU)."""
        tool_T_tip = np.eye(4)
        tool_T_tip[2, 3] = -self.guide_depth
        return tool_T_tip @ np.linalg.inv(self.oru_tip())

    def slot_T_oru(self) -> np.ndarray:
        """A seated ORU in its slot frame: bottom face on the slot floor."""
        T = np.eye(4)
        T[2, 3] = -self.slot_depth
        return T

    def seated_tool_pose(self, base_T_slot: np.ndarray) -> np.ndarray:
        """base_T_tool with the ORU in the slot fully captured by the end effector."""
        return base_T_slot @ self.slot_T_oru() @ np.linalg.inv(self.tool_T_oru())


class SceneConfig(StrictModel):
    name: str = "cell"
    stores: list[Store] = Field(min_length=1, max_length=16)
    orus: list[Oru] = Field(default_factory=list, max_length=16)
    geometry: CellGeometry = CellGeometry()

    @model_validator(mode="after")
    def _consistent(self) -> "SceneConfig":
        names = [s.name for s in self.stores]
        if len(set(names)) != len(names):
            raise ValueError(f"stores: duplicate names in {names}")
        oru_names = {o.name for o in self.orus}
        for s in self.stores:
            if s.holds is not None and s.holds not in oru_names:
                raise ValueError(f"store {s.name}: holds unknown ORU {s.holds!r} (known: {sorted(oru_names)})")
        return self

    def store(self, name: str) -> Store:
        for s in self.stores:
            if s.name == name:
                return s
        raise KeyError(f"no store {name!r} in scene {self.name} (known: {[s.name for s in self.stores]})")


    def with_true_offsets(self, offsets: dict[str, "ScenePose"]) -> "SceneConfig":
        """A copy whose named stores sit at these true offsets (a plant file's hidden placement
        errors replacing the cell file's); unknown names raise KeyError."""
        for name in offsets:
            self.store(name)
        stores = [s.model_copy(update={"true_offset": offsets[s.name]}) if s.name in offsets else s
                  for s in self.stores]
        return self.model_copy(update={"stores": stores})

    def oru(self, name: str) -> Oru:
        for o in self.orus:
            if o.name == name:
                return o
        raise KeyError(f"no ORU {name!r} in scene {self.name} (known: {[o.name for o in self.orus]})")


def load_scene(path: str | Path = DEFAULT_SCENE) -> SceneConfig:
    return load_toml_model(path, SceneConfig)
