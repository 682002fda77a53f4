"""A prismatic joint in the per-joint plant: a linear axis in its own units (m, N, kg). The
load on a slide is its weight along the axis, the same at every position; the position
sensor is a linear encoder with a step in metres; inconsistent fields are one clear line."""
from __future__ import annotations

import math

import pytest

from spacearm.base.config.errors import ConfigError
from spacearm.firmware_sim.plant import GRAVITY, JointParams, Plant, PlantConfig, load_plant_config

SCREW = 2 * math.pi / 0.01          # rad per m: a 10 mm lead ball screw


def _free_acceleration(params: dict, q: float, config: dict | None = None) -> float:
    """Link acceleration over one sub-step of a free joint (brake off, no servo) at q."""
    plant = Plant.create(1, PlantConfig(joints=[JointParams(initial_position=q, **params)], substeps=1,
                                        **(config or {})))
    joint = plant.joints[0]
    joint.brake_engaged = False
    h = 1e-3
    joint.substep(1.0, h)
    return joint.qd / h


def test_prismatic_load_does_not_depend_on_position() -> None:
    rail = {"kind": "prismatic", "gravity_torque": 400.0, "gravity_angle": 0.3, "link_inertia": 40.0,
            "gear_ratio": SCREW}
    accelerations = [_free_acceleration(rail, q) for q in (-0.5, 0.0, 0.2, 1.3)]
    mass = 3.0e-4 * SCREW ** 2 + 40.0
    for a in accelerations:
        assert a == pytest.approx(-400.0 * math.cos(0.3) / mass, rel=1e-12)
    # the same numbers on a revolute joint do depend on the position (G cos(q + angle))
    hinge = {k: v for k, v in rail.items() if k != "kind"}
    assert abs(_free_acceleration(hinge, 1.3) - _free_acceleration(hinge, 0.0)) > 0.1 * abs(accelerations[0])


def test_payload_on_a_slide_is_its_whole_weight() -> None:
    rail = {"kind": "prismatic", "gravity_angle": 0.0, "link_inertia": 40.0, "gear_ratio": SCREW}
    mass = 3.0e-4 * SCREW ** 2 + 40.0
    a = _free_acceleration(rail, 0.4, {"payload": {"mass_error": 2.0}})
    assert a == pytest.approx(-2.0 * GRAVITY / mass, rel=1e-12)


def test_linear_encoder_quantises_in_metres() -> None:
    default = Plant.create(1, PlantConfig(joints=[JointParams(kind="prismatic", initial_position=0.1234567)]))
    assert default.joints[0].q_measured == pytest.approx(0.123457, abs=1e-12)      # 1 um steps
    coarse = Plant.create(1, PlantConfig(joints=[JointParams(kind="prismatic", encoder_quantum=1e-4,
                                                             initial_position=0.1234567)]))
    assert coarse.joints[0].q_measured == pytest.approx(0.1235, abs=1e-12)
    assert JointParams(kind="prismatic").position_quantum == 1e-6
    assert JointParams().position_quantum == pytest.approx(25 * math.pi / 180 / 3600)


@pytest.mark.parametrize("table, words", [
    ('kind = "prismatic"\nresolver_arcsec = 10.0', "encoder_quantum (m)"),
    ("encoder_quantum = 1e-5", 'kind = "prismatic"'),
    ('kind = "prismatic"\npayload_lever = 0.5', "payload_lever"),
    ('kind = "linear"', "kind"),
])
def test_inconsistent_joint_fields_are_one_clear_line(tmp_path, table: str, words: str) -> None:
    path = tmp_path / "plant.toml"
    path.write_text(f"[[joints]]\n{table}\n")
    with pytest.raises(ConfigError) as exc:
        load_plant_config(path)
    message = str(exc.value)
    assert words in message and "joints #1" in message and "\n" not in message.strip()
