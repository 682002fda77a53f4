"""Plant-side parameters of the ORU cell's contact world (the `[contact]` table of a plant file).

Chosen values (the paper gives none):
- point stiffness 2.5e3 N/m and damping 30 N s/m per contact point: guide surfaces behind
  the test bed's compliant store mounts and end-effector guide blocks. A face flat against a
  wall touches with up to 8 of the 16 sample points (2e4 N/m); the floor carries the 4
  bottom corners (1e4 N/m: F_tz = 2.5 N is 0.25 mm). With the arm's ~8 kg effective tool
  mass sqrt(2e4/8) = 50 rad/s, well inside the 2 ms physics sub-step (h w = 0.1), and the
  20 ms admittance loop with its one-cycle delay stays stable: k_e = 2e4 N/m in
  configs/impedance.toml is checked by eq. 19 and the sampled-loop pole (a pure damper
  B = 500 N s/m is stable up to 2B/T = 5e4 N/m).
- friction 0.15 (anodised aluminium on itself, lubricated), regularised below 1 mm/s.
- end-effector 3.0 kg with its centroid 80 mm in front of the sensor; the sensor sits
  200 mm behind the tool point on the tool axis (Figure 7: sensor inside the end effector).
- grasp spring 2e5 N/m / 2e3 N m/rad: a clamped adapter whose ORU is still latched in its
  store; pulling against it shows up as a large wrench (the latch-not-released failure).
"""
from __future__ import annotations

from pathlib import Path

from pydantic import Field

from spacearm.base.paths import REPO_ROOT
from spacearm.base.config.loader import StrictModel
from spacearm.base.config.scene import ScenePose



class ContactConfig(StrictModel):
    scene: str = Field(default="configs/scene/oru_testbed.toml", description="cell file (repo-relative or absolute)")
    stiffness: float = Field(default=2.5e3, gt=0.0, le=1.0e7, description="N/m per contact point")
    damping: float = Field(default=30.0, ge=0.0, le=1.0e5, description="N s/m per contact point")
    friction: float = Field(default=0.15, ge=0.0, le=2.0, description="Coulomb coefficient")
    slip_velocity: float = Field(default=1.0e-3, gt=0.0, le=1.0, description="m/s friction regularisation")
    gravity: float = Field(default=9.81, ge=0.0, le=20.0, description="m/s^2 along -z of the base; 0 = orbit")
    ee_mass: float = Field(default=3.0, ge=0.0, le=100.0, description="kg of the end effector after the sensor")
    ee_centroid: tuple[float, float, float] = Field(default=(0.0, 0.0, 0.08), description="m, sensor frame")
    sensor_offset: float = Field(default=0.20, ge=0.0, le=2.0, description="m: the sensor origin sits this far behind the tool point on the tool axis")
    grasp_stiffness: float = Field(default=2.0e5, gt=0.0, le=1.0e8, description="N/m adapter in the clamped grip")
    grasp_rot_stiffness: float = Field(default=2.0e3, gt=0.0, le=1.0e6, description="N m/rad")
    latch_time: float = Field(default=1.0, gt=0.0, le=30.0, description="s for the store latch to open or close")
    near: float = Field(default=0.25, gt=0.0, le=5.0, description="m: contacts are only evaluated this close")
    store_offsets: dict[str, ScenePose] = Field(
        default_factory=dict, description="store name -> true offset (slot_nominal_T_slot_true): the plant's "
                                          "hidden placement errors, replacing the cell file's true_offset")

    def scene_path(self) -> Path:
        path = Path(self.scene)
        return path if path.is_absolute() else REPO_ROOT / path
