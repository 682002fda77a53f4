"""Impedance gains and limits (configs/impedance.toml), checked for stability on load.

Eq. 19 of the ORU paper (after [21]): the free-to-contact transition is stable when
alpha = k_e / k_d >> 1 and xi >= (sqrt(1 + alpha) - 1) / 2, with xi = b_d / (2 sqrt(m_d k_d)).
With m_d = 0 (the paper's choice) xi is unbounded and the condition always holds, so the
sampled loop is checked as well: the admittance reads the force of the position it commanded
one cycle earlier, x[k] = a x[k-1] - (1 - a) alpha x[k-1] (a = exp(-k_d T / b_d)), stable
when |a - (1 - a) alpha| < 1; for k_d = 0, |1 - T k_e / b_d| < 1.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import Field, model_validator

from spacearm.base.paths import CONFIGS
from spacearm.base.config.loader import StrictModel, load_toml_model

AXES = ("x", "y", "z", "rx", "ry", "rz")
Six = tuple[float, float, float, float, float, float]
DEFAULT_IMPEDANCE = CONFIGS / "impedance.toml"
POLE_MARGIN = 0.95     # |pole| above this is refused (too little damping left in contact)


@dataclass(frozen=True)
class AxisStability:
    axis: str
    alpha: float          # k_e / k_d (inf for k_d = 0)
    xi: float             # damping ratio of eq. 18 (inf for m_d = 0)
    xi_required: float    # eq. 19
    pole: float           # sampled-loop pole in contact
    stable: bool


@dataclass(frozen=True)
class StabilityReport:
    axes: tuple[AxisStability, ...]

    @property
    def stable(self) -> bool:
        return all(a.stable for a in self.axes)

    def problems(self) -> list[str]:
        return [f"{a.axis}: alpha {a.alpha:.3g}, xi {a.xi:.3g} (eq. 19 needs >= {a.xi_required:.3g}), "
                f"sampled pole {a.pole:+.3f} (needs |pole| < {POLE_MARGIN})" for a in self.axes if not a.stable]


class ImpedanceParams(StrictModel):
    period: float = Field(default=0.02, gt=0.0, le=1.0, description="s, the control cycle")
    damping: Six = Field(default=(500.0, 500.0, 500.0, 10.0, 10.0, 10.0), description="B_d: N s/m, N m s/rad")
    stiffness: Six = Field(default=(1000.0, 1000.0, 1000.0, 20.0, 20.0, 20.0), description="K_d: N/m, N m/rad")
    inertia: Six = Field(default=(0.0,) * 6, description="M_d (the paper: 0)")
    desired_wrench: Six = Field(default=(0.0,) * 6, description="F_d, N and N m")
    environment_stiffness: Six = Field(default=(4.0e4, 4.0e4, 4.0e4, 150.0, 150.0, 150.0),
                                       description="k_e for eq. 19: stiffest contact expected, N/m, N m/rad")
    step: float = Field(default=1.0e-4, gt=0.0, le=0.005, description="m per cycle along the insertion axis (dstep)")
    retract_step: float = Field(default=3.0e-4, gt=0.0, le=0.005,
                                description="m per cycle pulling out (extraction, withdrawal)")
    insert_force: float = Field(default=2.5, gt=0.0, le=100.0, description="N, F_tz: insertion stops above it")
    force_limit: float = Field(default=40.0, gt=0.0, le=300.0, description="N: protective stop above it")
    torque_limit: float = Field(default=4.0, gt=0.0, le=30.0, description="N m: protective stop above it")

    @model_validator(mode="after")
    def _stable(self) -> "ImpedanceParams":
        report = self.stability()
        if not report.stable:
            raise ValueError("impedance gains unstable in contact: " + "; ".join(report.problems()))
        return self

    def stability(self, axes: tuple[int, ...] = tuple(range(6))) -> StabilityReport:
        out = []
        for i in axes:
            k, b, m, ke = self.stiffness[i], self.damping[i], self.inertia[i], self.environment_stiffness[i]
            if b <= 0.0:
                out.append(AxisStability(AXES[i], math.inf, 0.0, math.inf, math.inf, False))
                continue
            alpha = ke / k if k > 0.0 else math.inf
            xi = b / (2.0 * math.sqrt(m * k)) if m > 0.0 and k > 0.0 else math.inf
            xi_required = (math.sqrt(1.0 + alpha) - 1.0) / 2.0 if math.isfinite(alpha) else 0.0
            if k > 0.0:
                a = math.exp(-k * self.period / b)
                pole = a - (1.0 - a) * alpha
            else:
                pole = 1.0 - self.period * ke / b
            ok = xi >= xi_required and abs(pole) < POLE_MARGIN
            out.append(AxisStability(AXES[i], alpha, xi, xi_required, pole, ok))
        return StabilityReport(tuple(out))

    def vector(self, name: str) -> np.ndarray:
        return np.asarray(getattr(self, name), float)


def load_impedance(path: str | Path = DEFAULT_IMPEDANCE) -> ImpedanceParams:
    return load_toml_model(path, ImpedanceParams)
