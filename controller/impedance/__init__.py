"""Position-based impedance control of the ORU paper (Section 4.3, Figure 16, eqs. 13-21)."""
from controller.impedance.admittance import Admittance
from controller.impedance.config import ImpedanceParams, StabilityReport, load_impedance
from controller.impedance.gravity import GravityModel
from controller.impedance.mode import ContactTask, ImpedanceMode

__all__ = ["Admittance", "ImpedanceParams", "StabilityReport", "load_impedance", "GravityModel",
           "ContactTask", "ImpedanceMode"]
