"""Position-based impedance control of the ORU paper (Section 4.3, Figure 16, eqs. 13-21)."""
from spacearm.controller.impedance.admittance import Admittance
from spacearm.controller.impedance.config import ImpedanceParams, StabilityReport, load_impedance
from spacearm.controller.impedance.gravity import GravityModel
from spacearm.controller.impedance.mode import ContactTask, ImpedanceMode

__all__ = ["Admittance", "ImpedanceParams", "StabilityReport", "load_impedance", "GravityModel",
           "ContactTask", "ImpedanceMode"]
