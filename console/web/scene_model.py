"""What the page draws that does not move with the arm: the cell of configs/scene/*.toml
(ORU stores, the ORUs seated in them, the marker on each ORU) and the arm's joint names and
limits. Poses are row-major 4x4 matrices in the arm's base frame (SI units)."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from spacearm.base.config.scene import SceneConfig, load_scene
from spacearm.base.kinematics.model import KinematicModel

STORE_WALL = 0.01   # m, drawn wall thickness of a store slot


def _flat(T: np.ndarray) -> list[float]:
    return np.round(np.asarray(T, float), 6).reshape(16).tolist()


def marker_description() -> dict[str, Any] | None:
    """Marker plate and circles (configs/vision/marker.toml), None if the vision config is absent."""
    try:
        from spacearm.base.vision.config import load_marker
        marker = load_marker()
    except Exception:  # noqa: BLE001 - vision config absent or invalid: the scene shows no marker
        return None
    return {"plate_size": list(marker.plate_size),
            "circle_diameter": marker.circle_diameter,
            "plate_thickness": marker.plate_thickness,
            "circles": [{"name": c.name, "xyz": list(c.xyz)} for c in marker.circles]}


def scene_description(scene: SceneConfig, model: KinematicModel, scene_path: Path) -> dict[str, Any]:
    g = scene.geometry
    oru_in_store = {s.holds: s for s in scene.stores if s.holds}
    stores = [{"name": s.name, "description": s.description, "pose": _flat(s.pose.matrix()),
               "inner": [g.oru_size[0] + 2 * g.slot_clearance, g.oru_size[1] + 2 * g.slot_clearance,
                         g.oru_size[2]], "wall": STORE_WALL}
              for s in scene.stores]
    orus = []
    for oru in scene.orus:
        store = oru_in_store.get(oru.name)
        if store is None:
            continue   # not seated in a store at the start: its pose comes from the task
        orus.append({"name": oru.name, "store": store.name,
                     "pose": _flat(store.pose.matrix() @ g.slot_T_oru()),
                     "size": list(g.oru_size), "adapter": list(g.adapter_size)})
    return {
        "scene": scene.name, "scene_file": str(scene_path),
        "arm": {"name": model.name, "joint_names": list(model.joint_names), "nq": model.nq,
                "q_min": list(model.q_min), "q_max": list(model.q_max), "v_max": list(model.v_max),
                "reach": model.reach, "base": _flat(model.base)},
        "stores": stores, "orus": orus, "marker": marker_description(),
    }


def load_scene_description(scene_path: Path, model: KinematicModel) -> dict[str, Any]:
    return scene_description(load_scene(scene_path), model, scene_path)
