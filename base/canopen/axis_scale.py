"""How a CiA 402 joint drive's wire values map to the joint: one object for both kinds of axis.

Position increments per joint unit come from the factor group: 608Fh (encoder increments
per motor revolutions) times 6091h (motor revolutions per shaft revolution) over the travel
of one shaft revolution. That travel is 6092h, the feed constant, on a linear axis (m per
shaft revolution, a screw's lead) and one turn, 2 pi rad, on a rotary one, which has no feed
constant here (its drive's 6092h, if any, is not read: its position unit is the shaft angle).

On the wire 6092h.1 (feed) is in micrometres (FEED_UNIT) per 6092h.2 shaft revolutions:
a 10 mm lead is 10000 / 1. The drive has no unit for it of its own (CiA 402 leaves the feed's
unit to the user-defined position unit), so both ends of this stack agree on um.

Torque: 6071h/6072h/6077h are per mille of 6076h, the motor's rated torque. At the joint that
is N m times the gear ratio on a rotary axis, and along a linear axis a force through the
ideal screw: F = T_motor * gear * 2 pi / lead.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from spacearm.base.canopen import od

FEED_UNIT = 1.0e-6        # m per 6092h.1 count on the wire


@dataclass(frozen=True)
class AxisScale:
    encoder_increments: int        # 608Fh.1
    motor_revolutions: int         # 608Fh.2
    gear_motor_revolutions: int    # 6091h.1
    gear_shaft_revolutions: int    # 6091h.2
    rated_torque: float            # N m, motor side (6076h)
    feed: int | None = None        # 6092h.1, um; None: a rotary axis
    feed_revolutions: int = 1      # 6092h.2

    @property
    def linear(self) -> bool:
        return self.feed is not None

    @property
    def travel_per_revolution(self) -> float:
        """Joint travel per shaft revolution: m on a linear axis, 2 pi rad on a rotary one."""
        if self.feed is None:
            return 2.0 * math.pi
        return self.feed * FEED_UNIT / self.feed_revolutions

    @property
    def per_unit(self) -> float:
        """Position increments per joint unit (rad, or m on a linear axis)."""
        return (self.encoder_increments / self.motor_revolutions * self.gear_motor_revolutions
                / self.gear_shaft_revolutions / self.travel_per_revolution)

    @property
    def rated_joint(self) -> float:
        """N m at the joint (N along a linear axis) for 1000 per mille of 6076h."""
        at_shaft = self.rated_torque * self.gear_motor_revolutions / self.gear_shaft_revolutions
        if self.feed is None:
            return at_shaft
        return at_shaft * 2.0 * math.pi / self.travel_per_revolution

    def with_reported(self, values: dict[tuple[int, int], int]) -> "AxisScale":
        """This scale with the drive's own reported 608Fh/6091h/6092h/6076h where it gave them
        (a 0 is no usable value and keeps the configured one)."""
        def get(index: int, sub: int, configured):
            return values.get((index, sub)) or configured
        return AxisScale(
            encoder_increments=get(od.POSITION_ENCODER_RESOLUTION, 1, self.encoder_increments),
            motor_revolutions=get(od.POSITION_ENCODER_RESOLUTION, 2, self.motor_revolutions),
            gear_motor_revolutions=get(od.GEAR_RATIO, 1, self.gear_motor_revolutions),
            gear_shaft_revolutions=get(od.GEAR_RATIO, 2, self.gear_shaft_revolutions),
            rated_torque=get(od.MOTOR_RATED_TORQUE, 0, round(self.rated_torque * 1000)) / 1000.0,
            feed=get(od.FEED_CONSTANT, 1, self.feed) if self.linear else None,
            feed_revolutions=get(od.FEED_CONSTANT, 2, self.feed_revolutions))

    def wire_objects(self) -> list[tuple[int, int, int]]:
        """(index, sub, value) of the hardware data this scale stands for (6092h only if linear)."""
        objects = [(od.POSITION_ENCODER_RESOLUTION, 1, self.encoder_increments),
                   (od.POSITION_ENCODER_RESOLUTION, 2, self.motor_revolutions),
                   (od.GEAR_RATIO, 1, self.gear_motor_revolutions),
                   (od.GEAR_RATIO, 2, self.gear_shaft_revolutions),
                   (od.MOTOR_RATED_TORQUE, 0, round(self.rated_torque * 1000))]
        if self.linear:
            objects += [(od.FEED_CONSTANT, 1, self.feed), (od.FEED_CONSTANT, 2, self.feed_revolutions)]
        return objects


def feed_counts(feed_constant: float) -> int:
    """A feed constant (m per shaft revolution) as 6092h.1 counts (um)."""
    return round(feed_constant / FEED_UNIT)
