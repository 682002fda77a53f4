"""Safety limits and closed-loop tuning of an arm, as configuration (the arm file's
`[supervision]` and `[approach]` tables; the following-error window is per joint, in
`[joints.drive]`). Every key is optional: the defaults are the values the
ORU test bed was commissioned with; an arm file overrides what differs for its arm and sensors."""
from __future__ import annotations

import math

from pydantic import Field

from spacearm.base.config.loader import StrictModel


class SupervisionConfig(StrictModel):
    position_margin: float = Field(0.0087, ge=0.0, le=0.2, description="rad beyond a soft limit before stopping")
    velocity_tolerance: float = Field(0.2, ge=0.0, le=2.0, description="fraction above v_max before stopping")
    wrench_force_limit: float = Field(150.0, gt=0.0, le=1.0e4, description="N")
    wrench_torque_limit: float = Field(30.0, gt=0.0, le=1.0e3, description="N m")
    # consecutive cycles without a node's PDOs (100 ms at 50 Hz, below the 250 ms heartbeat-loss detection)
    missing_pdo_cycles: int = Field(5, ge=1, le=100)
    # A wrench step this large from one cycle to the next is not a contact the arm can make at its
    # speeds (ORU insertion forces build over many cycles): a sensor or cable fault.
    ft_jump_force: float = Field(80.0, gt=0.0, le=1.0e4, description="N per cycle")
    ft_jump_torque: float = Field(15.0, gt=0.0, le=1.0e3, description="N m per cycle")
    # Frozen sensor: a live F/T sensor is never bit-for-bit constant (noise). The check arms itself
    # once the reading changed in `ft_live_changes` consecutive cycles and then stops on
    # `ft_frozen_cycles` identical readings in a row (0 switches the check off).
    ft_frozen_cycles: int = Field(25, ge=0, le=10000)
    ft_live_changes: int = Field(3, ge=1, le=1000)


class ApproachConfig(StrictModel):
    """The closed-loop (visual servo) approach."""
    gain: float = Field(1.5, gt=0.0, le=20.0, description="1/s, twist = gain x pose error")
    tol_position: float = Field(0.0004, gt=0.0, le=0.05, description="m, measured remaining error to finish")
    tol_rotation: float = Field(math.radians(0.08), gt=0.0, le=0.2, description="rad")
    still_speed: float = Field(0.0005, gt=0.0, le=0.1, description="m/s: the arm counts as still below this")
    lost_frames: int = Field(6, ge=1, le=1000, description="consecutive frames without a pose -> vision_lost")
    no_frame_timeout: float = Field(10.0, gt=0.0, le=600.0, description="s of controller time without any frame")
    # A result whose exposure is this old (controller time) when it arrives is stale: the camera
    # or the vision worker fell behind. Lockstep runs see up to ~1 s (the renderer's wall time
    # in fast cycles); the goal from an old frame is still right for a static target, so the
    # bound is generous and the approach holds still meanwhile.
    stale_after: float = Field(3.0, gt=0.0, le=600.0, description="s of controller time between exposure and use")
    max_start_distance: float = Field(0.6, gt=0.0, le=10.0, description="m")
    grow_margin: float = Field(0.01, gt=0.0, le=1.0, description="m above the smallest measured error -> error_grows")
    damping: float = Field(0.02, gt=0.0, le=1.0, description="DLS damping of the Jacobian pseudo-inverse")
