"""`calibrate fit --apply`: the arm file's [calibration] table from a trusted fit, with provenance.

Joint corrections go to dtheta/dalpha/da/dd/dbeta; the base and tool frame corrections to
dbase/dtool, but only when those frames are the arm's own (the error model's world/tool nominal
is the identity): a registration to an external measurement frame (motion capture, tracker) or
an instrument's tool point is not part of the arm and is written as a provenance comment.
"""
from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from spacearm.controller.calibration.errormodel import ErrorModel
from spacearm.controller.calibration.fit_checks import group_of
from spacearm.controller.calibration.laser_routine import write_calibrated_arm
from spacearm.controller.calibration.trusted_fit import FitReport
from spacearm.base.config.arm import Calibration


def calibration_table(em: ErrorModel, report: FitReport, data: list[str], method: str) -> tuple[Calibration, list[str]]:
    """The [calibration] table and the provenance comment lines."""
    if not report.verdict.ok:
        raise ValueError(report.verdict.message())
    est = report.estimate
    n = em.kin.nq

    def per_joint(kind: str) -> list[float]:
        return [est.get(f"{kind}_{i + 1}", 0.0) for i in range(n)]

    def frame(which: str, nominal: np.ndarray) -> tuple[list[float], bool]:
        names = em.frame_names(which)
        values = [est.get(nm, 0.0) for nm in names]
        own = np.allclose(nominal, np.eye(4))
        return (values if own and any(values) else []), own

    dbase, base_own = frame("world", em.world_nominal)
    dtool, tool_own = frame("tool", em.tool_nominal)
    before, after = report.held_rms("before"), report.held_rms("after")
    table = Calibration(
        method=f"calibrate fit: {method}", date=datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        data=", ".join(data), configurations=report.train_postures,
        residual_rms=report.train_position_rms,
        validation_rms_before=before, validation_rms_after=after,
        dtheta=per_joint("theta"), dalpha=per_joint("alpha"), da=per_joint("a"), dd=per_joint("d"),
        dbeta=per_joint("beta"), dbase=dbase, dtool=dtool)
    notes = [f"estimated: {', '.join(report.result.free)}",
             f"not identifiable on this data: {', '.join(d.name for d in report.identifiability.dropped) or 'none'}",
             f"rank {report.identifiability.rank}, condition {report.identifiability.condition:.3g}, "
             f"residual / stated noise {report.noise_ratio:.2f}"]
    arm_kinds = ("theta", "d", "a", "alpha", "beta")
    other = {k: v for k, v in est.items() if k.rsplit("_", 1)[0] not in arm_kinds
             and not (base_own and k in em.frame_names("world")) and not (tool_own and k in em.frame_names("tool"))}
    if not base_own:
        notes.append("measurement-frame registration (not written to the arm): nominal "
                     + np.array2string(em.world_nominal[:3], precision=6).replace("\n", ""))
    notes += [f"instrument/registration {k} = {v:+.6g} +- {report.std.get(k, float('nan')):.2g}"
              for k, v in other.items()]
    return table, notes


def apply(nominal_arm: Path, out: Path, em: ErrorModel, report: FitReport, data: list[str], method: str) -> None:
    compliant = [n for n in report.result.free if group_of(n) == "joint_compliance"]
    if compliant:
        # An arm file holds geometry only: writing the rest would silently drop the load terms.
        raise ValueError(f"the fit estimated joint compliances ({', '.join(compliant)}); an arm file has no place "
                         "for them, so its geometry alone would not reproduce the fit")
    table, notes = calibration_table(em, report, data, method)
    write_calibrated_arm(nominal_arm, table, out, command="calibrate fit", comments=notes)

