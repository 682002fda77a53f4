"""Physical effects of the simulated hardware, as small pure functions the plant calls.

Each effect is off by default (its parameter zero) and set per joint or per sensor in the
plant TOML; the controller and the diagnosis tool never see these parameters.
"""
from spacearm.firmware_sim.effects.friction import friction_torque, static_friction
from spacearm.firmware_sim.effects.transmission import dead_zone, transmission_error, transmission_error_slope
from spacearm.firmware_sim.effects.sensors import DelayLine, ft_sensor_error
from spacearm.firmware_sim.effects.thermal import TemperatureProfile

__all__ = ["friction_torque", "static_friction", "dead_zone", "transmission_error", "transmission_error_slope",
           "DelayLine", "ft_sensor_error", "TemperatureProfile"]
